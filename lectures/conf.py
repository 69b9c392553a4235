"""Sphinx configuration of the course site: the rendered lectures, as stored (nothing is executed).

Build it with ``python -m sphinx -b html lectures lectures/_build/html`` (or ``python lectures/render.py
--site``) after ``python lectures/render.py`` has stored the outputs in the notebooks.
"""

project = "LAGO with cvxpy — a course"
author = "the lago_cvx authors"
copyright = "the lago_cvx authors, BSD-3-Clause"

extensions = ["myst_nb"]
nb_execution_mode = "off"            # the outputs stored by render.py are shown as they are
nb_merge_streams = True
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 2

root_doc = "index"
# The notebooks are the pages; their paired .py files, the exercise solutions and everything Jupyter
# leaves behind are not.
exclude_patterns = [
    "_build", "solutions", "**/.ipynb_checkpoints", "*.nbconvert.ipynb", ".jupyter_cache", "jupyter_execute",
]
suppress_warnings = ["myst.header"]   # lectures may jump from the title (#) to a sub-section (###)

html_theme = "alabaster"
html_title = project
html_theme_options = {"page_width": "1100px", "sidebar_width": "260px"}
html_show_sourcelink = False
html_last_updated_fmt = None         # no build date: the site is reproducible
