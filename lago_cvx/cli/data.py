"""``lago-cvx datasets``: list, verify and fetch the public benchmark graphs (``lago_cvx.datasets``)."""

from __future__ import annotations

from .common import EXIT_BAD_INPUT, EXIT_OK, UsageError, emit


def _names(args):
    """The manifest's names of ``args.names`` (a full name, or a unique basename or stem: ``CSAIL``);
    ``UsageError`` (exit 2) for an unknown or ambiguous one, listing candidates."""
    from ..datasets import DATASET_FILES, DatasetNotFound, resolve_name

    if not args.names:
        return list(DATASET_FILES)
    out = []
    for n in args.names:
        try:
            out.append(resolve_name(n))
        except DatasetNotFound as exc:
            raise UsageError(f"{exc} (`lago-cvx datasets list` shows them all)") from None
    return out


def cmd_datasets(args) -> int:
    from .. import datasets as D

    action = args.action
    names = _names(args)
    if action == "list":
        rows = []
        table = {row[0]: row for row in D.DATASET_TABLE}
        for f in names:
            src, p = D.MANIFEST[f], D.locate(f)
            rows.append({"file": f, "poses": table[f][1], "edges": table[f][2], "path": str(p) if p else None,
                         "sha256": src.sha256, "source": D.source_url(f), "repository": src.repository,
                         "commit": src.commit, "repository_path": src.path, "licence": src.licence,
                         "chi2_min": D.REFERENCE_CHI2.get(f)})
        found = sum(r["path"] is not None for r in rows)
        lines = [f"{len(rows)} datasets, {found} found (lookup: $LAGO_CVX_DATASETS, ../shared/datasets beside the "
                 f"checkout, the cache {D.cache_dir()})"]
        for r in rows:
            lines.append(f"  {r['file']:<38} {r['poses']:>6} poses {r['edges']:>6} edges  "
                         + (r["path"] if r["path"] else "missing")
                         + f"\n      source {r['source']}")
        emit(args, {"datasets": rows, "n_found": found}, lines)
        return EXIT_OK
    if action == "verify":
        report = D.verify(names)
        rows = [{"file": f, "path": str(p) if p else None, "status": st} for f, p, st in report]
        bad = [r for r in rows if r["status"] == "mismatch"]
        found = [r for r in rows if r["status"] != "missing"]
        lines = [f"  {r['status']:<9} {r['file']}" + (f"  ({r['path']})" if r["path"] else "") for r in rows]
        lines.append(f"{len(found)} of {len(rows)} found; {len(found) - len(bad)} match the manifest's SHA-256"
                     + (f"; {len(bad)} DIFFER from their public source" if bad else ""))
        emit(args, {"datasets": rows, "n_found": len(found), "n_mismatch": len(bad)}, lines)
        return EXIT_BAD_INPUT if bad else EXIT_OK
    if action == "fetch":
        paths = D.fetch(names, progress=not args.json)
        rows = [{"file": f, "path": str(p)} for f, p in zip(names, paths)]
        emit(args, {"datasets": rows}, [f"  {r['file']}: {r['path']}" for r in rows])
        return EXIT_OK
    # path
    if len(names) != 1 or not args.names:
        raise UsageError("`lago-cvx datasets path NAME` takes exactly one dataset name")
    p = D.dataset(names[0])
    emit(args, {"file": names[0], "path": str(p)}, [str(p)])
    return EXIT_OK


def add_parser(sub) -> None:
    s = sub.add_parser(
        "datasets", help="list, verify (SHA-256) or fetch the public benchmark graphs",
        description="The public benchmark graphs (SE-Sync's, L. Carlone's, GTSAM's toy graph) with the SHA-256 "
                    "and public source of each file. They are looked up in $LAGO_CVX_DATASETS, then in "
                    "../shared/datasets beside the checkout, then in the download cache ($LAGO_CVX_CACHE or "
                    "~/.cache/lago_cvx/datasets). `fetch` downloads the missing ones into the cache (needs "
                    "network and `pip install \"lago-cvx[datasets]\"`).")
    s.add_argument("action", nargs="?", choices=["list", "verify", "fetch", "path"], default="list")
    s.add_argument("names", nargs="*", metavar="NAME", help="dataset names, e.g. se-sync/MIT.g2o, or a unique basename or stem "
                                                       "(MIT.g2o, MIT) (default: all)")
    s.add_argument("--json", action="store_true", help="print one JSON object")
    s.set_defaults(func=cmd_datasets)
