/* The sparse engine's kernels (lago_cvx.sparse.compiled) in C99, loaded by ctypes (lago_cvx.sparse.c_kernels),
 * which checks every index they read first (lago_cvx.sparse.kernel_checks). Indices int64, reals double, bool
 * arrays one byte each; outputs and scratch are passed in, no function keeps state (threads may call them at once
 * on different data). Built with -ffp-contract=off (no fused multiply-add). The Python module at the end is empty:
 * it only makes the built file an importable extension module. */

#include <Python.h>

#include <math.h>
#include <stdint.h>
#include <string.h>

#if defined(_WIN32)
#define CK_API __declspec(dllexport)
#else
#define CK_API __attribute__((visibility("default")))
#endif

typedef int64_t i64;

/* LAPACK/BLAS of SciPy's cython_lapack / cython_blas, Fortran convention (every argument by pointer). */
typedef void (*potrf_t)(char *, int *, double *, int *, int *);
typedef void (*trsm_t)(char *, char *, char *, char *, int *, int *, double *, double *, int *, double *, int *);
typedef void (*syrk_t)(char *, char *, int *, int *, double *, double *, int *, double *, double *, int *);

/* Front f's matrix in F (column-major D x D, lower triangle): N's blocks in its pivot columns from the
 * edges' A_k, B_k (m, nq, b), then the extend-add of its children's updates popped from the stack.
 * Returns D. */
static i64 ck_assemble(i64 f, i64 b, const i64 *fptr, const i64 *rptr, const i64 *rel, const i64 *nchild,
                       const i64 *bptr, const i64 *border, const i64 *bli, const i64 *blj, const uint8_t *btr,
                       const double *A, const double *B, i64 m, i64 nq, double *F, const double *stack,
                       const i64 *st_front, const i64 *st_off, i64 *state)
{
    i64 k = (fptr[f + 1] - fptr[f]) * b;
    i64 r = (rptr[f + 1] - rptr[f]) * b;
    i64 D = k + r;
    for (i64 i = 0; i < D * D; i++)
        F[i] = 0.0;
    for (i64 q = bptr[f]; q < bptr[f + 1]; q++) {
        i64 kind = border[q] / m;
        i64 e = border[q] - kind * m;
        const double *X = (kind >= 1 ? B : A) + e * nq * b; /* the block is X^T Y */
        const double *Y = (kind == 1 ? B : A) + e * nq * b;
        i64 li = bli[q] * b;
        i64 lj = blj[q] * b;
        for (i64 i = 0; i < b; i++) {
            for (i64 j = 0; j < b; j++) {
                double v = 0.0;
                if (btr[q]) {
                    for (i64 s = 0; s < nq; s++)
                        v += X[s * b + j] * Y[s * b + i];
                } else {
                    for (i64 s = 0; s < nq; s++)
                        v += X[s * b + i] * Y[s * b + j];
                }
                F[(li + i) + (lj + j) * D] += v;
            }
        }
    }
    i64 top = state[0];
    i64 nc = nchild[f];
    for (i64 s = top - nc; s < top; s++) {
        i64 c = st_front[s];
        i64 off = st_off[s];
        i64 r0 = rptr[c];
        i64 pc = rptr[c + 1] - r0;
        i64 rc = pc * b;
        for (i64 jp = 0; jp < pc; jp++) {
            for (i64 jc = 0; jc < b; jc++) {
                i64 jj = jp * b + jc;
                i64 dst = (rel[r0 + jp] * b + jc) * D;
                i64 src = off + jj * rc;
                i64 base = dst + rel[r0 + jp] * b; /* the column's first pose: components jc ... b - 1 */
                for (i64 ic = jc; ic < b; ic++)
                    F[base + ic] += stack[src + jp * b + ic];
                for (i64 ip = jp + 1; ip < pc; ip++) {
                    base = dst + rel[r0 + ip] * b;
                    i64 sb = src + ip * b;
                    for (i64 ic = 0; ic < b; ic++)
                        F[base + ic] += stack[sb + ic];
                }
            }
        }
    }
    state[0] = top - nc;
    return D;
}

/* Keep front f's block column [L_PP; X] in L (packed columns), push its update U on the stack. */
static void ck_finish(i64 f, i64 b, const i64 *fptr, const i64 *rptr, const i64 *Lptr, double *L, const double *F,
                      double *stack, i64 *st_front, i64 *st_off, i64 *state)
{
    i64 k = (fptr[f + 1] - fptr[f]) * b;
    i64 r = (rptr[f + 1] - rptr[f]) * b;
    i64 D = k + r;
    i64 base = Lptr[f];
    for (i64 j = 0; j < k; j++) {
        i64 dst = base + j * D - j * (j + 1) / 2;
        i64 src = j * D;
        for (i64 i = j; i < D; i++)
            L[dst + i] = F[src + i];
    }
    if (r > 0) {
        i64 top = state[0];
        i64 off = st_off[top];
        for (i64 j = 0; j < r; j++) {
            i64 src = (k + j) * D + k;
            i64 dst = off + j * r;
            for (i64 i = j; i < r; i++)
                stack[dst + i] = F[src + i];
        }
        st_front[top] = f;
        st_off[top + 1] = off + r * r;
        state[0] = top + 1;
    }
}

/* F[i, c] -= sum_{p0 <= p < p1} F[i, p] F[c, p] for the columns c0 <= c < c1, rows i >= max(i0, c). */
static void ck_update_rest(double *F, i64 D, i64 p0, i64 p1, i64 c0, i64 c1, i64 i0)
{
    for (i64 c = c0; c < c1; c++) {
        for (i64 i = i0 > c ? i0 : c; i < D; i++) {
            double v = F[c * D + i];
            for (i64 p = p0; p < p1; p++)
                v -= F[p * D + i] * F[p * D + c];
            F[c * D + i] = v;
        }
    }
}

#if defined(__GNUC__)
/* The same for every column c >= c0, four columns by 2W rows at a time in vectors of W doubles held in
 * registers (the few entries above the diagonal this touches are never read). */
#define CK_TILE(OP) OP(a0, 0, 0); OP(b0, 0, w); OP(a1, 1, 0); OP(b1, 1, w); OP(a2, 2, 0); OP(b2, 2, w); OP(a3, 3, 0); OP(b3, 3, w)
#define CK_LOAD(v, q, o) memcpy(&v, F + (c + q) * D + i + o, sizeof(V))
#define CK_STORE(v, q, o) memcpy(F + (c + q) * D + i + o, &v, sizeof(V))
#define CK_SUB(v, q, o) v -= (o ? y : x) * P[c + q]
#define CK_UPDATE(NAME, W)                                                                                   \
    static void NAME(double *F, i64 D, i64 p0, i64 p1, i64 c0)                                               \
    {                                                                                                        \
        typedef double V __attribute__((vector_size(8 * W)));                                               \
        const i64 w = W;                                                                                     \
        i64 c = c0, i = 0;                                                                                   \
        for (; c + 4 <= D; c += 4) {                                                                         \
            for (i = c; i + 2 * W <= D; i += 2 * W) {                                                        \
                V a0, b0, a1, b1, a2, b2, a3, b3, x, y;                                                      \
                CK_TILE(CK_LOAD);                                                                            \
                for (const double *P = F + p0 * D; P < F + p1 * D; P += D) {                                 \
                    memcpy(&x, P + i, sizeof(V));                                                            \
                    memcpy(&y, P + i + W, sizeof(V));                                                        \
                    CK_TILE(CK_SUB);                                                                         \
                }                                                                                            \
                CK_TILE(CK_STORE);                                                                           \
            }                                                                                                \
            ck_update_rest(F, D, p0, p1, c, c + 4, i);                                                       \
        }                                                                                                    \
        ck_update_rest(F, D, p0, p1, c, D, 0);                                                               \
    }
CK_UPDATE(ck_update2, 2)
#if defined(__x86_64__) || defined(__i386__)
__attribute__((target("avx2"))) CK_UPDATE(ck_update4, 4)
#define CK_UPDATE_ANY(...) (__builtin_cpu_supports("avx2") ? ck_update4(__VA_ARGS__) : ck_update2(__VA_ARGS__))
#else
#define CK_UPDATE_ANY ck_update2
#endif
#else
/* The same pivot by pivot, for compilers without vector extensions (each entry's subtractions in pivot order). */
static void CK_UPDATE_ANY(double *F, i64 D, i64 p0, i64 p1, i64 c0)
{
    for (i64 p = p0; p < p1; p++)
        for (i64 c = c0; c < D; c++)
            for (i64 i = c; i < D; i++)
                F[c * D + i] -= F[p * D + i] * F[p * D + c];
}
#endif

/* Partial Cholesky of the column-major D x D front F, right-looking by panels of CK_PANEL columns: a panel's
 * columns one by one (updating the panel), then the columns right of it at once (CK_UPDATE_ANY). Every entry
 * gets its subtractions in pivot order, without fused multiply-add, so the bits are those of the column-by-column
 * loop on every processor. Returns 0, or j + 1 when pivot j is not positive. */
#define CK_PANEL 16
static i64 ck_dense(double *F, i64 D, i64 k)
{
    for (i64 j0 = 0; j0 < k; j0 += CK_PANEL) {
        i64 j1 = j0 + CK_PANEL < k ? j0 + CK_PANEL : k;
        for (i64 j = j0; j < j1; j++) {
            i64 cj = j * D;
            double djj = F[cj + j];
            if (!(djj > 0.0))
                return j + 1;
            djj = sqrt(djj);
            F[cj + j] = djj;
            double inv = 1.0 / djj;
            for (i64 i = j + 1; i < D; i++)
                F[cj + i] *= inv;
            ck_update_rest(F, D, j, j + 1, j + 1, j1, 0);
        }
        if (j1 < D)
            CK_UPDATE_ANY(F, D, j0, j1, j1);
    }
    return 0;
}

/* The same by LAPACK/BLAS at the addresses fn (potrf, trsm, syrk): L_PP = potrf(F_PP),
 * X = trsm(F_RP, L_PP), U = syrk(F_RR, X), in place. Returns LAPACK's info (0: done). */
static i64 ck_dense_blas(double *F, i64 D, i64 k, const i64 *fn)
{
    int kk = (int)k, dd = (int)D, r = (int)(D - k), info = 0;
    char cL = 'L', cR = 'R', cT = 'T', cN = 'N';
    double one = 1.0, minus = -1.0;
    ((potrf_t)(intptr_t)fn[0])(&cL, &kk, F, &dd, &info);
    if (info != 0)
        return info;
    if (r > 0) {
        ((trsm_t)(intptr_t)fn[1])(&cR, &cL, &cT, &cN, &r, &kk, &one, F, &dd, F + k, &dd);
        ((syrk_t)(intptr_t)fn[2])(&cL, &cN, &r, &kk, &minus, F + k, &dd, &one, F + (k + k * D), &dd);
    }
    return 0;
}

/* Fronts f0, f0 + 1, ... up to f1 or the first front marked big. Returns the front it stopped at, or
 * -(f + 1) for a front whose pivot block is not positive definite. */
CK_API i64 ck_run(i64 f0, i64 f1, const uint8_t *big, i64 b, const i64 *fptr, const i64 *rptr, const i64 *rel,
                  const i64 *nchild, const i64 *Lptr, const i64 *bptr, const i64 *border, const i64 *bli,
                  const i64 *blj, const uint8_t *btr, const double *A, const double *B, i64 m, i64 nq, double *L,
                  double *F, double *stack, i64 *st_front, i64 *st_off, i64 *state, i64 small_work, const i64 *fn)
{
    for (i64 f = f0; f < f1; f++) {
        if (big[f])
            return f;
        i64 D = ck_assemble(f, b, fptr, rptr, rel, nchild, bptr, border, bli, blj, btr, A, B, m, nq, F, stack,
                            st_front, st_off, state);
        i64 k = (fptr[f + 1] - fptr[f]) * b;
        if (k * D * D >= small_work) {
            if (ck_dense_blas(F, D, k, fn) != 0)
                return -(f + 1);
        } else if (ck_dense(F, D, k) != 0) {
            return -(f + 1);
        }
        ck_finish(f, b, fptr, rptr, Lptr, L, F, stack, st_front, st_off, state);
    }
    return f1;
}

/* Front f's sizes for the sweeps, the slots of its update variables written to slot. */
static void front_sizes(i64 f, i64 b, const i64 *fptr, const i64 *rptr, const i64 *rows, const i64 *Lptr,
                        i64 *slot, i64 *k, i64 *r, i64 *D, i64 *s0, i64 *base)
{
    i64 pr = rptr[f + 1] - rptr[f];
    *k = (fptr[f + 1] - fptr[f]) * b;
    for (i64 p = 0; p < pr; p++)
        for (i64 c = 0; c < b; c++)
            slot[p * b + c] = rows[rptr[f] + p] * b + c;
    *r = pr * b;
    *D = *k + pr * b;
    *s0 = fptr[f] * b;
    *base = Lptr[f];
}

/* L z = y in place for Y (nr, ncol), over the fronts seq (children first); slot, t scratch (rmax). */
CK_API void ck_forward(double *Y, i64 nr, i64 ncol, const i64 *seq, i64 nseq, i64 b, const i64 *fptr,
                       const i64 *rptr, const i64 *rows, const i64 *Lptr, const double *L, i64 *slot, double *t)
{
    i64 k, r, D, s0, base;
    for (i64 q = 0; q < nseq; q++) {
        front_sizes(seq[q], b, fptr, rptr, rows, Lptr, slot, &k, &r, &D, &s0, &base);
        for (i64 c = 0; c < nr; c++) {
            double *y = Y + c * ncol;
            for (i64 i = 0; i < r; i++)
                t[i] = 0.0;
            for (i64 j = 0; j < k; j++) {
                i64 col = base + j * D - j * (j + 1) / 2;
                double v = y[s0 + j] / L[col + j];
                y[s0 + j] = v;
                if (v != 0.0) {
                    for (i64 i = j + 1; i < k; i++)
                        y[s0 + i] -= L[col + i] * v;
                    for (i64 i = 0; i < r; i++)
                        t[i] += L[col + k + i] * v;
                }
            }
            for (i64 i = 0; i < r; i++)
                y[slot[i]] -= t[i];
        }
    }
}

/* L^T x = z in place for Y (nr, ncol), over the fronts seq (parents first); slot, t scratch (rmax). */
CK_API void ck_backward(double *Y, i64 nr, i64 ncol, const i64 *seq, i64 nseq, i64 b, const i64 *fptr,
                        const i64 *rptr, const i64 *rows, const i64 *Lptr, const double *L, i64 *slot, double *t)
{
    i64 k, r, D, s0, base;
    for (i64 q = 0; q < nseq; q++) {
        front_sizes(seq[q], b, fptr, rptr, rows, Lptr, slot, &k, &r, &D, &s0, &base);
        for (i64 c = 0; c < nr; c++) {
            double *y = Y + c * ncol;
            for (i64 i = 0; i < r; i++)
                t[i] = y[slot[i]];
            for (i64 j = k - 1; j >= 0; j--) {
                i64 col = base + j * D - j * (j + 1) / 2;
                double v = y[s0 + j];
                for (i64 i = j + 1; i < k; i++)
                    v -= L[col + i] * y[s0 + i];
                for (i64 i = 0; i < r; i++)
                    v -= L[col + k + i] * t[i];
                y[s0 + j] = v / L[col + j];
            }
        }
    }
}

/* Local pose index of position p in front g (p must be in the front). */
static i64 local_index(i64 g, i64 p, const i64 *fptr, const i64 *rptr, const i64 *rows)
{
    if (fptr[g] <= p && p < fptr[g + 1])
        return p - fptr[g];
    i64 lo = rptr[g], hi = rptr[g + 1];
    while (lo < hi) {
        i64 mid = (lo + hi) / 2;
        if (rows[mid] < p)
            lo = mid + 1;
        else
            hi = mid;
    }
    return fptr[g + 1] - fptr[g] + lo - rptr[g];
}

CK_API void ck_pose_local(const i64 *f, const i64 *pos, i64 n, const i64 *fptr, const i64 *rptr, const i64 *rows,
                          i64 *out)
{
    for (i64 t = 0; t < n; t++)
        out[t] = local_index(f[t], pos[t], fptr, rptr, rows);
}

/* block_map's first pass: bptr (nf + 1,) the boundaries of the pairs by front. Returns their number. */
CK_API i64 ck_block_count(const i64 *prow, const i64 *pcol, i64 nt, const i64 *position, const i64 *front_of,
                          i64 nf, i64 *bptr)
{
    for (i64 g = 0; g <= nf; g++)
        bptr[g] = 0;
    for (i64 t = 0; t < nt; t++) {
        if (prow[t] >= 0 && pcol[t] >= 0) {
            i64 a = position[prow[t]], c = position[pcol[t]];
            bptr[front_of[a < c ? a : c] + 1] += 1;
        }
    }
    for (i64 g = 0; g < nf; g++)
        bptr[g + 1] += bptr[g];
    return bptr[nf];
}

/* block_map's second pass (fill (nf,) scratch). */
CK_API void ck_block_fill(const i64 *prow, const i64 *pcol, i64 nt, const i64 *position, const i64 *front_of,
                          const i64 *fptr, const i64 *rptr, const i64 *rows, i64 nf, const i64 *bptr, i64 *fill,
                          i64 *order, i64 *li, i64 *lj, uint8_t *transposed)
{
    for (i64 g = 0; g < nf; g++)
        fill[g] = bptr[g];
    for (i64 t = 0; t < nt; t++) {
        if (prow[t] < 0 || pcol[t] < 0)
            continue;
        i64 pr = position[prow[t]], pc = position[pcol[t]];
        i64 lo = pr < pc ? pr : pc, hi = pr < pc ? pc : pr;
        i64 g = front_of[lo];
        i64 s = fill[g];
        fill[g] += 1;
        order[s] = t;
        transposed[s] = pr < pc;
        lj[s] = lo - fptr[g];
        li[s] = local_index(g, hi, fptr, rptr, rows);
    }
}

/* M x of the edge system: A, B (m, q, b), t, h (m,), x (d, b, nr), out (m, q, nr). */
CK_API void ck_edge_matvec(const double *A, const double *B, i64 m, i64 q, i64 b, const i64 *t, const i64 *h,
                           const double *x, i64 nr, double *out)
{
    for (i64 k = 0; k < m; k++) {
        i64 tk = t[k], hk = h[k];
        for (i64 s = 0; s < q; s++) {
            const double *a = A + (k * q + s) * b, *bb = B + (k * q + s) * b;
            for (i64 j = 0; j < nr; j++) {
                double o = 0.0;
                for (i64 c = 0; c < b; c++) {
                    double xt = tk >= 0 ? x[(tk * b + c) * nr + j] : 0.0;
                    double xh = hk >= 0 ? x[(hk * b + c) * nr + j] : 0.0;
                    if (c == 0)
                        o = a[0] * xt;
                    else
                        o += a[c] * xt;
                    o += bb[c] * xh;
                }
                out[(k * q + s) * nr + j] = o;
            }
        }
    }
}

/* M^T r: r (m, q, nr), out (d, b, nr) zeroed by the caller; every tail's A_k^T r_k, then every head's. */
CK_API void ck_edge_rmatvec(const double *A, const double *B, i64 m, i64 q, i64 b, const i64 *t, const i64 *h,
                            const double *r, i64 nr, double *out)
{
    for (int pass = 0; pass < 2; pass++) {
        const double *J = pass == 0 ? A : B;
        const i64 *ends = pass == 0 ? t : h;
        for (i64 k = 0; k < m; k++) {
            i64 e = ends[k];
            if (e < 0)
                continue;
            for (i64 c = 0; c < b; c++) {
                for (i64 j = 0; j < nr; j++) {
                    double u = J[(k * q) * b + c] * r[(k * q) * nr + j];
                    for (i64 s = 1; s < q; s++)
                        u += J[(k * q + s) * b + c] * r[(k * q + s) * nr + j];
                    out[(e * b + c) * nr + j] += u;
                }
            }
        }
    }
}

/* The most stack entries alive at once while the fronts seq are factored in that order (lev (n + 1,)
 * scratch). */
CK_API i64 ck_stack_peak(const i64 *seq, i64 n, const i64 *nchild, const i64 *sizes, i64 *lev)
{
    i64 top = 0, peak = 0;
    for (i64 i = 0; i <= n; i++)
        lev[i] = 0;
    for (i64 t = 0; t < n; t++) {
        i64 f = seq[t];
        top -= nchild[f];
        if (top < 0)
            top = 0;
        if (sizes[f] > 0) {
            lev[top + 1] = lev[top] + sizes[f];
            top += 1;
            if (lev[top] > peak)
                peak = lev[top];
        }
    }
    return peak;
}

/* For fronts in postorder: each subtree's total work and its first front. */
CK_API void ck_subtrees(const i64 *parent, const double *work, i64 n, double *total, i64 *first)
{
    for (i64 f = 0; f < n; f++) {
        total[f] = work[f];
        first[f] = f;
    }
    for (i64 f = 0; f < n; f++) {
        i64 p = parent[f];
        if (p >= 0) {
            total[p] += total[f];
            if (first[f] < first[p])
                first[p] = first[f];
        }
    }
}

/* supernodes.relax: relaxed amalgamation (k, true_nnz updated in place; top (ns,) out). */
CK_API void ck_relax(i64 *k, const i64 *r, i64 *true_nnz, const i64 *sparent, i64 ns, i64 n0, i64 n1, i64 n2,
                     double z0, double z1, double z2, i64 *top)
{
    for (i64 c = 0; c < ns; c++)
        top[c] = c;
    for (i64 c = 0; c < ns; c++) {
        i64 p = sparent[c];
        if (p < 0)
            continue;
        i64 kk = k[c] + k[p];
        i64 total = kk * (kk + 1) / 2 + kk * r[p];
        double zf = (double)(total - true_nnz[c] - true_nnz[p]) / (double)total;
        if (kk <= n0 || (kk <= n1 && zf < z0) || (kk <= n2 && zf < z1) || zf < z2) {
            k[p] = kk;
            true_nnz[p] += true_nnz[c];
            top[c] = p;
        }
    }
}

/* supernodes.postorder: order (n,) out; size, free (n + 1,) scratch. */
CK_API void ck_postorder(const i64 *parent, i64 n, i64 *size, i64 *free_, i64 *order)
{
    for (i64 i = 0; i <= n; i++) {
        size[i] = 1;
        free_[i] = 0;
    }
    for (i64 i = 0; i < n; i++)
        size[parent[i] < 0 ? n : parent[i]] += size[i];
    for (i64 i = n - 1; i >= 0; i--) {
        i64 p = parent[i] < 0 ? n : parent[i];
        i64 lo = free_[p];
        free_[p] = lo + size[i];
        free_[i] = lo;
        order[lo + size[i] - 1] = i;
    }
}

static struct PyModuleDef ckernels_module = {PyModuleDef_HEAD_INIT, "_ckernels",
                                             "The sparse engine's kernels in C, called through ctypes "
                                             "(lago_cvx.sparse.c_kernels).",
                                             -1, NULL, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__ckernels(void)
{
    return PyModule_Create(&ckernels_module);
}
