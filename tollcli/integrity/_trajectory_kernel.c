/* Compiled twin of one pass of the trajectory filter and of the combination of two passes (trajectory_pass_twin.py
 * holds the same steps in Python).
 *
 * The two give the same bits: every sum is taken in the same order, nothing is fused or reordered (built with
 * -ffp-contract=off, no -ffast-math), and the only library calls are sqrt (exact) and the sine and cosine of a
 * heading (the C library's, as Python's math module calls them). The Earth's turn during a signal's flight
 * (θ ≲ 1e-5 rad) is taken by its Taylor series, whose remainder is below 1e-20 of θ for |θ| < 1e-3.
 * tests/test_trajectory_kernel.py compares the two, bit for bit, on the real Berlin drive and on simulated drives
 * with and without odometry. The Python twin stays the reference and the fallback where this module was not built,
 * so an invoice does not depend on the build.
 *
 * No numpy headers: arrays come through the buffer protocol (C-contiguous, float64 unless said).
 *
 * Speed without changing a bit: the dense algebra is written once with the matrix size a parameter and inlined for
 * the sizes of one to four clocks (the compiler unrolls it); independent factorisations (the two information
 * matrices, the two weights a halving step tries) run in lock-step, so that one's square roots and divisions wait
 * while the other's proceed. The pass hands the combination the information matrices it made (the prior's inverse,
 * the posterior's matrix before it was factored), and the combination solves x from the factor its chosen weight's
 * trace came from: no matrix is inverted twice.
 *
 * Why this file is long: the pass's four steps (clocks started, prediction, robust update, widening), the
 * combination, the small dense algebra they need (Cholesky, its solve and inverse, one and two at a time), and the
 * argument checking of two entry points.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define M 6          /* motion states before the clocks (trajectory_filter.MOTION_STATES) */
#define EARTH_RADIUS_M 6371000.0  /* trajectory_pass_twin.EARTH_RADIUS_M */
#define N_NOISE 11   /* MotionNoise's fields, in trajectory_filter.NOISE_FIELDS order */
#define MAX_STATES 64
#define INLINE static inline __attribute__((always_inline))

typedef struct {
    Py_ssize_t n_epochs, n_slots;
    int n_states, n_clocks, odometry, direction, iterations, lost_min, keep_prior, keep_post;
    double omega, c_mps, cauchy, relinearise;
    const double *t, *sat, *pr, *sigma2, *robust2, *speed, *yaw, *forward, *left, *wander, *origin, *rot, *noise;
    const uint8_t *mask;
    const int64_t *clock;
} Pass;

/* noise fields (trajectory_filter.NOISE_FIELDS) */
enum { ALONG, SHARE, POSITION, GAP_SPEED, YAW, HEADING, UP, CLOCK, DRIFT, ACCEL, GYRO_BIAS };

/* ranges (m) and east-north-up unit vectors from the position x[0..2] to the n used satellites of epoch k */
static void ranges(const Pass *c, const double *x, Py_ssize_t k, const int *used, int n, double *rng, double *u) {
    const double *r = c->rot, *o = c->origin;
    double pos[3];
    for (int i = 0; i < 3; i++) pos[i] = o[i] + ((r[i] * x[0] + r[3 + i] * x[1]) + r[6 + i] * x[2]);
    for (int a = 0; a < n; a++) {
        const double *s = c->sat + (k * c->n_slots + used[a]) * 3;
        double dx = s[0] - pos[0], dy = s[1] - pos[1], dz = s[2] - pos[2];
        double rough = sqrt((dx * dx + dy * dy) + dz * dz);
        double theta = c->omega * rough / c->c_mps, t2 = theta * theta;
        double ct = 1.0 - t2 / 2.0 * (1.0 - t2 / 12.0), st = theta * (1.0 - t2 / 6.0 * (1.0 - t2 / 20.0));
        double v0 = (ct * s[0] + st * s[1]) - pos[0];
        double v1 = ((-st) * s[0] + ct * s[1]) - pos[1];
        double v2 = s[2] - pos[2];
        double d = sqrt((v0 * v0 + v1 * v1) + v2 * v2);
        double e0 = v0 / d, e1 = v1 / d, e2 = v2 / d;
        rng[a] = d;
        for (int b = 0; b < 3; b++) u[a * 3 + b] = (e0 * r[b * 3] + e1 * r[b * 3 + 1]) + e2 * r[b * 3 + 2];
    }
}

/* a (n×n) = L Lᵀ, L written over a's lower triangle; 0 where a is not positive definite */
INLINE int cholesky_n(double *a, const int n) {
    for (int j = 0; j < n; j++) {
        double d = a[j * n + j];
        for (int k = 0; k < j; k++) d -= a[j * n + k] * a[j * n + k];
        if (!(d > 0.0) || !isfinite(d)) return 0;
        d = sqrt(d);
        a[j * n + j] = d;
        double r = 1.0 / d;
        for (int i = j + 1; i < n; i++) {
            double s = a[i * n + j];
            for (int k = 0; k < j; k++) s -= a[i * n + k] * a[j * n + k];
            a[i * n + j] = s * r;
        }
    }
    return 1;
}

/* b := (L Lᵀ)⁻¹ b */
INLINE void cholesky_solve_n(const double *l, const int n, double *b) {
    for (int i = 0; i < n; i++) {
        double s = b[i];
        for (int k = 0; k < i; k++) s -= l[i * n + k] * b[k];
        b[i] = s / l[i * n + i];
    }
    for (int i = n - 1; i >= 0; i--) {
        double s = b[i];
        for (int k = i + 1; k < n; k++) s -= l[k * n + i] * b[k];
        b[i] = s / l[i * n + i];
    }
}

/* out := (L Lᵀ)⁻¹ = L⁻ᵀ L⁻¹ (symmetric); li: n×n work */
INLINE void cholesky_inverse_n(const double *l, const int n, double *li, double *out) {
    for (int j = 0; j < n; j++) li[j * n + j] = 1.0 / l[j * n + j];
    for (int j = 0; j < n; j++)
        for (int i = j + 1; i < n; i++) {
            double s = 0.0;
            for (int k = j; k < i; k++) s -= l[i * n + k] * li[k * n + j];
            li[i * n + j] = s * li[i * n + i];
        }
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j++) {
            double s = 0.0;
            for (int k = i; k < n; k++) s += li[k * n + i] * li[k * n + j];
            out[i * n + j] = s;
            out[j * n + i] = s;
        }
}

/* cholesky_n of two matrices at once, step by step in lock-step so that one's square roots and divisions overlap the
 * other's (the same operations on each, so the same bits); bit 1 of the result: a is positive definite, bit 2: b */
INLINE int cholesky2_n(double *a, double *b, const int n) {
    int ok = 3;
    for (int j = 0; j < n; j++) {
        double da = a[j * n + j], db = b[j * n + j];
        for (int k = 0; k < j; k++) {
            da -= a[j * n + k] * a[j * n + k];
            db -= b[j * n + k] * b[j * n + k];
        }
        if (!(da > 0.0) || !isfinite(da)) { ok &= ~1; da = 1.0; } /* (that one is dropped: any number goes on) */
        if (!(db > 0.0) || !isfinite(db)) { ok &= ~2; db = 1.0; }
        if (!ok) return 0;
        da = sqrt(da);
        db = sqrt(db);
        a[j * n + j] = da;
        b[j * n + j] = db;
        double ra = 1.0 / da, rb = 1.0 / db;
        for (int i = j + 1; i < n; i++) {
            double sa = a[i * n + j], sb = b[i * n + j];
            for (int k = 0; k < j; k++) {
                sa -= a[i * n + k] * a[j * n + k];
                sb -= b[i * n + k] * b[j * n + k];
            }
            a[i * n + j] = sa * ra;
            b[i * n + j] = sb * rb;
        }
    }
    return ok;
}

/* cholesky_inverse_n of two factors at once, in lock-step (the same bits) */
INLINE void cholesky_inverse2_n(const double *la, const double *lb, const int n, double *lia, double *lib, double *oa,
                                double *ob) {
    for (int j = 0; j < n; j++) {
        lia[j * n + j] = 1.0 / la[j * n + j];
        lib[j * n + j] = 1.0 / lb[j * n + j];
    }
    for (int j = 0; j < n; j++)
        for (int i = j + 1; i < n; i++) {
            double sa = 0.0, sb = 0.0;
            for (int k = j; k < i; k++) {
                sa -= la[i * n + k] * lia[k * n + j];
                sb -= lb[i * n + k] * lib[k * n + j];
            }
            lia[i * n + j] = sa * lia[i * n + i];
            lib[i * n + j] = sb * lib[i * n + i];
        }
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j++) {
            double sa = 0.0, sb = 0.0;
            for (int k = i; k < n; k++) {
                sa += lia[k * n + i] * lia[k * n + j];
                sb += lib[k * n + i] * lib[k * n + j];
            }
            oa[i * n + j] = sa;
            oa[j * n + i] = sa;
            ob[i * n + j] = sb;
            ob[j * n + i] = sb;
        }
}

/* The algebra above for the state counts of one to four clocks written out with n a constant (the compiler unrolls
 * it), any other n as is: the same operations in the same order, so the same bits. */
#define BY_STATES(call, n) switch (n) { case 7: call(7); case 8: call(8); case 9: call(9); case 10: call(10); default: call(n); }
static void cholesky_solve(const double *l, int n, double *b) {
#define C_(k) cholesky_solve_n(l, k, b); return
    BY_STATES(C_, n)
#undef C_
}
static void cholesky_inverse(const double *l, int n, double *li, double *out) {
#define C_(k) cholesky_inverse_n(l, k, li, out); return
    BY_STATES(C_, n)
#undef C_
}

/* p := F p Fᵀ for F = I + Σ v·e_i e_jᵀ over the entries (i, j, v), then symmetrised; fp, work: n×n */
INLINE void transition(double *p, const int n, const int *ei, const int *ej, const double *ev, int ne, double *fp) {
    memcpy(fp, p, sizeof(double) * n * n);
    for (int e = 0; e < ne; e++)
        for (int b = 0; b < n; b++) fp[ei[e] * n + b] += ev[e] * p[ej[e] * n + b];
    memcpy(p, fp, sizeof(double) * n * n);
    for (int e = 0; e < ne; e++)
        for (int a = 0; a < n; a++) p[a * n + ei[e]] += ev[e] * fp[a * n + ej[e]];
    for (int a = 0; a < n; a++)
        for (int b = 0; b < a; b++) {
            double s = (p[a * n + b] + p[b * n + a]) * 0.5;
            p[a * n + b] = s;
            p[b * n + a] = s;
        }
}

/* the tangent plane at the log's origin leaves the Earth's surface: a road at (e, n) lies (e² + n²) / 2R below it (785 m
   100 km out), so a height that follows the road falls by the change of that as the vehicle moves from (e0, n0) — a
   height random walk cannot follow it (on a simulated 100 km drive: 766 epochs beyond their bound without this) */
INLINE void follow_surface(double *x, double e0, double n0) {
    x[2] -= ((x[0] * x[0] + x[1] * x[1]) - (e0 * e0 + n0 * n0)) / (2.0 * EARTH_RADIUS_M);
}

/* the state dt_s later (direction -1: earlier), through the interval ending at epoch `interval` */
INLINE void predict(const Pass *c, double *x, double *p, double dt, Py_ssize_t interval, double *fp, const int n) {
    int drift = M - 1, ne = 0, ei[MAX_STATES + 8], ej[MAX_STATES + 8];
    double ev[MAX_STATES + 8], q[MAX_STATES];
    const double *nz = c->noise;
    double dir = (double)c->direction, s = dir * dt;
    for (int g = M; g < n; g++) {
        x[g] += x[drift] * s;
        ei[ne] = g; ej[ne] = drift; ev[ne++] = s;
    }
    if (c->odometry) {
        double v = c->speed[interval], w = c->yaw[interval], fw = c->forward[interval], lf = c->left[interval];
        for (int a = 0; a < n; a++) q[a] = 0.0;
        if (isfinite(v) && isfinite(w) && isfinite(fw) && isfinite(lf)) {
            double psi, dpsi;
            x[3] -= (w - x[4]) * s;
            ei[ne] = 3; ej[ne] = 4; ev[ne++] = s;
            if (c->direction < 0) { psi = x[3]; dpsi = s; } else { psi = x[3] + (w - x[4]) * s; dpsi = 0.0; }
            double sn = sin(psi), cs = cos(psi);
            double de = fw * sn - lf * cs, dn = fw * cs + lf * sn, e0 = x[0], n0 = x[1];
            x[0] += dir * de;
            x[1] += dir * dn;
            follow_surface(x, e0, n0);
            ei[ne] = 0; ej[ne] = 3; ev[ne++] = dir * dn;
            ei[ne] = 1; ej[ne] = 3; ev[ne++] = -(dir * de);
            ei[ne] = 0; ej[ne] = 4; ev[ne++] = dir * dn * dpsi;
            ei[ne] = 1; ej[ne] = 4; ev[ne++] = -(dir * de) * dpsi;
            double sv = nz[ALONG] + nz[SHARE] * fabs(v);
            double lat = 0.5 * nz[YAW] * dt * fabs(fw);
            double ae = sv * dt * sn, an = sv * dt * cs, ay = nz[YAW] * dt;
            q[0] = (ae * ae + nz[POSITION] * dt) + lat * lat;
            q[1] = (an * an + nz[POSITION] * dt) + lat * lat;
            q[3] = ay * ay + nz[HEADING] * dt;
        } else { /* an interval without odometry: the position wanders (as far as the vehicle may have gone since the
                    last interval with odometry: trajectory_filter.wander_m2), the heading too */
            q[0] = c->wander[interval];
            q[1] = c->wander[interval];
            q[3] = 0.1 * dt;
        }
        q[2] = nz[UP] * dt;
        q[4] = nz[GYRO_BIAS] * dt;
        for (int g = M; g < n; g++) q[g] = nz[CLOCK] * dt;
        q[drift] = nz[DRIFT] * dt;
        transition(p, n, ei, ej, ev, ne, fp);
        for (int a = 0; a < n; a++) p[a * n + a] += q[a];
        return;
    }
    double e0 = x[0], n0 = x[1];
    x[0] += x[3] * s;
    x[1] += x[4] * s;
    follow_surface(x, e0, n0);
    ei[ne] = 0; ej[ne] = 3; ev[ne++] = s;
    ei[ne] = 1; ej[ne] = 4; ev[ne++] = s;
    transition(p, n, ei, ej, ev, ne, fp);
    double qa = nz[ACCEL];
    for (int axis = 0; axis < 2; axis++) {
        int ps = axis, vl = axis + 3;
        double cross = qa * s * dt / 2.0;
        p[ps * n + ps] += qa * dt * dt * dt / 3.0;
        p[ps * n + vl] += cross;
        p[vl * n + ps] += cross;
        p[vl * n + vl] += qa * dt;
    }
    p[2 * n + 2] += nz[UP] * dt;
    for (int g = M; g < n; g++) p[g * n + g] += nz[CLOCK] * dt;
    p[drift * n + drift] += nz[DRIFT] * dt;
}

static void sort_values(double *v, int n) { /* insertion sort: a handful of values */
    for (int i = 1; i < n; i++) {
        double t = v[i];
        int j = i - 1;
        while (j >= 0 && v[j] > t) { v[j + 1] = v[j]; j--; }
        v[j + 1] = t;
    }
}

/* clock groups seen for the first time: their clock from this epoch's measurements (median), variance 100² m² */
static void start_clocks(const Pass *c, double *x, double *p, uint8_t *started, Py_ssize_t k, const int *used, int n,
                         double *rng, double *u, double *values) {
    int any = 0, ns = c->n_states;
    for (int a = 0; a < n; a++) if (!started[c->clock[k * c->n_slots + used[a]]]) any = 1;
    if (!any) return;
    ranges(c, x, k, used, n, rng, u);
    for (int g = 0; g < c->n_clocks; g++) {
        if (started[g]) continue;
        int count = 0;
        for (int a = 0; a < n; a++)
            if (c->clock[k * c->n_slots + used[a]] == g) values[count++] = c->pr[k * c->n_slots + used[a]] - rng[a];
        if (!count) continue;
        sort_values(values, count);
        int col = M + g;
        x[col] = count % 2 ? values[count / 2] : (values[count / 2 - 1] + values[count / 2]) / 2.0;
        for (int a = 0; a < ns; a++) { p[col * ns + a] = 0.0; p[a * ns + col] = 0.0; }
        p[col * ns + col] = ((10000.0 + p[0]) + p[ns + 1]) + p[2 * ns + 2];
        started[g] = 1;
    }
}

typedef struct { /* work arrays of the update */
    double *info, *a, *li, *x, *b, *rng, *u, *z, *w, *a_info;
    int info_ok, a_ok; /* info: the prior's information matrix; a_info: the posterior's (A before it is factored) */
} Work;

/* the robust (Cauchy, iteratively reweighted) update of epoch k from the prior (xp, pp), in information form;
 * writes x, p, z, w; 0 where a matrix was not positive definite (x, p then the prior's, z NaN, w 0) */
INLINE int update(const Pass *c, const double *xp, const double *pp, Py_ssize_t k, const int *used, int n, double *x_out,
                  double *p_out, Work *wk, const int ns) {
    size_t nn = (size_t)ns * ns;
    double *x = wk->x;
    wk->info_ok = wk->a_ok = 0;
    memcpy(wk->info, pp, sizeof(double) * nn);
    if (!cholesky_n(wk->info, ns)) goto failed;
    cholesky_inverse_n(wk->info, ns, wk->li, wk->info);
    wk->info_ok = 1;
    memcpy(x, xp, sizeof(double) * ns);
    for (int it = 0; it < c->iterations; it++) {
        ranges(c, x, k, used, n, wk->rng, wk->u);
        memcpy(wk->a, wk->info, sizeof(double) * nn);
        for (int a = 0; a < ns; a++) wk->b[a] = 0.0;
        for (int i = 0; i < n; i++) {
            Py_ssize_t slot = k * c->n_slots + used[i];
            int idx[4] = {0, 1, 2, M + (int)c->clock[slot]};
            double h[4] = {-wk->u[i * 3], -wk->u[i * 3 + 1], -wk->u[i * 3 + 2], 1.0};
            double hd = 0.0, sd = 0.0;
            for (int a = 0; a < 4; a++) hd += h[a] * (xp[idx[a]] - x[idx[a]]);
            for (int a = 0; a < 4; a++) {
                double t = 0.0;
                for (int b = 0; b < 4; b++) t += pp[idx[a] * ns + idx[b]] * h[b];
                sd += h[a] * t;
            }
            double r = ((c->pr[slot] - wk->rng[i]) - x[idx[3]]) - hd;
            double zi = r / sqrt(sd + c->robust2[slot]);
            double qz = zi / c->cauchy;
            double wi = 1.0 / (1.0 + qz * qz);
            double wd = wi / c->sigma2[slot];
            wk->z[i] = zi;
            wk->w[i] = wi;
            for (int a = 0; a < 4; a++) {
                double wh = wd * h[a];
                for (int b = 0; b < 4; b++) wk->a[idx[a] * ns + idx[b]] += wh * h[b];
                wk->b[idx[a]] += (wd * r) * h[a];
            }
        }
        memcpy(wk->a_info, wk->a, sizeof(double) * nn);
        if (!cholesky_n(wk->a, ns)) goto failed;
        cholesky_solve_n(wk->a, ns, wk->b);
        double change = 0.0;
        for (int a = 0; a < ns; a++) {
            double xn = xp[a] + wk->b[a];
            if (a < 3 && fabs(xn - x[a]) > change) change = fabs(xn - x[a]);
            x[a] = xn;
        }
        if (change < c->relinearise) break;
    }
    cholesky_inverse_n(wk->a, ns, wk->li, p_out);
    memcpy(x_out, x, sizeof(double) * ns);
    wk->a_ok = 1;
    return 1;
failed:
    memcpy(x_out, xp, sizeof(double) * ns);
    memcpy(p_out, pp, sizeof(double) * nn);
    for (int i = 0; i < n; i++) { wk->z[i] = NAN; wk->w[i] = 0.0; }
    return 0;
}

/* the prior of an epoch whose measurements the pass mostly rejected, widened (trajectory_filter._widened) */
static void widen(double *p, int ns, int odometry) {
    for (int a = 0; a < 3; a++) p[a * ns + a] += 10000.0;
    for (int g = M; g < ns; g++) p[g * ns + g] += 10000.0;
    p[3 * ns + 3] += odometry ? 0.5 * 0.5 : 10.0 * 10.0;
    p[4 * ns + 4] += odometry ? 0.01 * 0.01 : 10.0 * 10.0;
}

/* run_pass's walk over the epochs (n_states S): see run_pass */
INLINE void pass_loop_n(const Pass *c, int resume, double *x, double *p, double *fp, double *xq, double *pq, double *values,
                        int *used, uint8_t *started, Work *wk, double *prior_x, double *prior_p, double *post_x,
                        double *post_p, double *z_all, double *w_all, uint8_t *started_all, uint8_t *relocked,
                        double *prior_y, double *post_y, const int S) {
    Py_ssize_t E = c->n_epochs, N = c->n_slots;
    size_t nn = (size_t)S * S;
    Py_ssize_t previous = -1;
    for (Py_ssize_t step = 0; step < E; step++) {
        Py_ssize_t k = c->direction > 0 ? step : E - 1 - step;
        if (resume && step == 0) { /* the state given is this epoch's posterior: go on from it */
            previous = k;
            continue;
        }
        if (previous >= 0) predict(c, x, p, fabs(c->t[k] - c->t[previous]), k > previous ? k : previous, fp, S);
        int n = 0;
        for (Py_ssize_t j = 0; j < N; j++) if (c->mask[k * N + j]) used[n++] = (int)j;
        if (n) start_clocks(c, x, p, started, k, used, n, wk->rng, wk->u, values);
        if (c->keep_prior) {
            memcpy(prior_x + k * S, x, sizeof(double) * S);
            memcpy(prior_p + k * nn, p, sizeof(double) * nn);
        }
        memcpy(started_all + k * c->n_clocks, started, c->n_clocks);
        if (n) {
            int ok = update(c, x, p, k, used, n, xq, pq, wk, S);
            int low = 0;
            for (int i = 0; i < n; i++) low += wk->w[i] < 0.5;
            if (ok && n >= c->lost_min && 2 * low > n) { /* the pass has lost the vehicle */
                widen(p, S, c->odometry);
                if (c->keep_prior) memcpy(prior_p + k * nn, p, sizeof(double) * nn);
                relocked[k] = 1;
                update(c, x, p, k, used, n, xq, pq, wk, S);
            }
            memcpy(x, xq, sizeof(double) * S);
            memcpy(p, pq, sizeof(double) * nn);
            for (int i = 0; i < n; i++) { z_all[k * N + used[i]] = wk->z[i]; w_all[k * N + used[i]] = wk->w[i]; }
        }
        /* the information matrices of the prior and the posterior (the last update's), NaN where there are none */
        if (c->keep_prior) {
            if (n && wk->info_ok) memcpy(prior_y + k * nn, wk->info, sizeof(double) * nn);
            else for (size_t i = 0; i < nn; i++) prior_y[k * nn + i] = NAN;
        }
        if (c->keep_post) {
            if (n && wk->a_ok) memcpy(post_y + k * nn, wk->a_info, sizeof(double) * nn);
            else for (size_t i = 0; i < nn; i++) post_y[k * nn + i] = NAN;
        }
        if (c->keep_post) {
            memcpy(post_x + k * S, x, sizeof(double) * S);
            memcpy(post_p + k * nn, p, sizeof(double) * nn);
        }
        previous = k;
    }
}

static void pass_loop(const Pass *c, int resume, double *x, double *p, double *fp, double *xq, double *pq, double *values,
                      int *used, uint8_t *started, Work *wk, double *prior_x, double *prior_p, double *post_x, double *post_p,
                      double *z_all, double *w_all, uint8_t *started_all, uint8_t *relocked, double *prior_y, double *post_y,
                      int S) {
#define C_(k) pass_loop_n(c, resume, x, p, fp, xq, pq, values, used, started, wk, prior_x, prior_p, post_x, post_p, z_all, \
                          w_all, started_all, relocked, prior_y, post_y, k); return
    BY_STATES(C_, S)
#undef C_
}

/* release the buffers an entry point took, and give its result: None where it got that far (ok), else NULL */
static PyObject *finish(Py_buffer *b, int n, int ok) {
    for (int i = 0; i < n; i++) if (b[i].obj) PyBuffer_Release(&b[i]);
    if (!ok) return NULL;
    Py_RETURN_NONE;
}

static int check(Py_buffer *b, Py_ssize_t items, Py_ssize_t itemsize, const char *name) {
    if (b->len != items * itemsize) {
        PyErr_Format(PyExc_ValueError, "%s: %zd bytes, %zd expected", name, b->len, items * itemsize);
        return 0;
    }
    return 1;
}

#define N_IN 18
#define N_OUT 10

/* run_pass(t, sat, pr, mask, clock, sigma2, robust2, speed, yaw, forward, left, wander, origin, rot, noise, start_x, start_p,
 *          start_started, prior_x, prior_p, post_x, post_p, z, w, started, relocked, prior_y, post_y,
 *          direction, odometry, n_clocks, iterations, lost_min, keep_prior, keep_post, resume, omega, c_mps, cauchy,
 *          relinearise)
 * keep_prior / keep_post 0: the priors / posteriors are not kept (their arrays empty; a pass's other half is what the
 * combination reads: the forward posteriors, the backward priors). prior_y / post_y (kept with them): their
 * information matrices, the inverses the update made (the prior's) or inverted (the posterior's), so that the
 * combination need not invert them again; all NaN at an epoch without an update (no measurement, a matrix not
 * positive definite).
 * start_started (n_clocks bytes): the clock groups started before the first epoch visited. resume 1: the pass goes on
 * from where another left it — start_x / start_p / start_started are its state after the first epoch visited, which
 * is not visited again (nothing of it written): the rest is what one pass over the whole would give, bit for bit.
 * Arrays as trajectory_pass_twin.run_pass takes them; outputs filled in place (those of epochs not visited left). */
static PyObject *run_pass(PyObject *self, PyObject *args) {
    Py_buffer in[N_IN], out[N_OUT];
    Pass c;
    memset(in, 0, sizeof(in));
    memset(out, 0, sizeof(out));
    int resume = 0;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*y*y*y*y*y*y*y*y*y*y*y*w*w*w*w*w*w*w*w*w*w*iiiiiiiidddd", &in[0], &in[1], &in[2],
                          &in[3], &in[4], &in[5], &in[6], &in[7], &in[8], &in[9], &in[10], &in[11], &in[12], &in[13], &in[14],
                          &in[15], &in[16], &in[17], &out[0], &out[1], &out[2], &out[3], &out[4], &out[5], &out[6], &out[7],
                          &out[8], &out[9],
                          &c.direction, &c.odometry, &c.n_clocks, &c.iterations, &c.lost_min, &c.keep_prior, &c.keep_post, &resume,
                          &c.omega, &c.c_mps, &c.cauchy, &c.relinearise))
        return NULL;
    PyObject *result = NULL;
    Py_ssize_t E = in[0].len / 8, N = E ? in[2].len / 8 / E : 0;
    int S = M + c.n_clocks;
    c.n_epochs = E;
    c.n_slots = N;
    c.n_states = S;
    if (c.n_clocks < 0 || S > MAX_STATES) {
        PyErr_SetString(PyExc_ValueError, "run_pass: n_clocks out of range");
        goto done;
    }
    if (!check(&in[1], E * N * 3, 8, "sat") || !check(&in[2], E * N, 8, "pr") || !check(&in[3], E * N, 1, "mask") ||
        !check(&in[4], E * N, 8, "clock") || !check(&in[5], E * N, 8, "sigma2") || !check(&in[6], E * N, 8, "robust2") ||
        !check(&in[7], E, 8, "speed") || !check(&in[8], E, 8, "yaw") || !check(&in[9], E, 8, "forward") ||
        !check(&in[10], E, 8, "left") || !check(&in[11], E, 8, "wander") || !check(&in[12], 3, 8, "origin") || !check(&in[13], 9, 8, "rot") ||
        !check(&in[14], N_NOISE, 8, "noise") || !check(&in[15], S, 8, "start_x") || !check(&in[16], S * S, 8, "start_p") || !check(&in[17], c.n_clocks, 1, "start_started") ||
        !check(&out[0], c.keep_prior ? E * S : 0, 8, "prior_x") || !check(&out[1], c.keep_prior ? E * S * S : 0, 8, "prior_p") ||
        !check(&out[2], c.keep_post ? E * S : 0, 8, "post_x") || !check(&out[3], c.keep_post ? E * S * S : 0, 8, "post_p") || !check(&out[4], E * N, 8, "z") ||
        !check(&out[5], E * N, 8, "w") || !check(&out[6], E * c.n_clocks, 1, "started") ||
        !check(&out[7], E, 1, "relocked") || !check(&out[8], c.keep_prior ? E * S * S : 0, 8, "prior_y") ||
        !check(&out[9], c.keep_post ? E * S * S : 0, 8, "post_y"))
        goto done;
    for (Py_ssize_t i = 0; i < E * N; i++) {
        int64_t g = ((const int64_t *)in[4].buf)[i];
        if (((const uint8_t *)in[3].buf)[i] && (g < 0 || g >= c.n_clocks)) {
            PyErr_SetString(PyExc_ValueError, "run_pass: a clock index out of range");
            goto done;
        }
    }
    c.t = in[0].buf; c.sat = in[1].buf; c.pr = in[2].buf; c.mask = in[3].buf; c.clock = in[4].buf;
    c.sigma2 = in[5].buf; c.robust2 = in[6].buf; c.speed = in[7].buf; c.yaw = in[8].buf; c.forward = in[9].buf;
    c.left = in[10].buf; c.wander = in[11].buf; c.origin = in[12].buf; c.rot = in[13].buf; c.noise = in[14].buf;
    double *prior_x = out[0].buf, *prior_p = out[1].buf, *post_x = out[2].buf, *post_p = out[3].buf;
    double *z_all = out[4].buf, *w_all = out[5].buf;
    uint8_t *started_all = out[6].buf, *relocked = out[7].buf;
    double *prior_y = out[8].buf, *post_y = out[9].buf;
    size_t nn = (size_t)S * S, slots = N > 0 ? (size_t)N : 1;
    double *mem = malloc(sizeof(double) * (8 * nn + 3 * S + 8 * slots));
    int *used = malloc(sizeof(int) * slots);
    uint8_t *started = calloc(c.n_clocks + 1, 1);
    if (!mem || !used || !started) {
        free(mem); free(used); free(started);
        PyErr_NoMemory();
        goto done;
    }
    double *x = mem, *p = x + S, *fp = p + nn, *xq = fp + nn, *pq = xq + S, *values = pq + nn;
    Work wk = {values + slots, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    wk.a = wk.info + nn; wk.li = wk.a + nn; wk.x = wk.li + nn; wk.b = wk.x + S;
    wk.rng = wk.b + S; wk.u = wk.rng + slots; wk.z = wk.u + 3 * slots; wk.w = wk.z + slots; wk.a_info = wk.w + slots;
    memcpy(x, in[15].buf, sizeof(double) * S);
    memcpy(p, in[16].buf, sizeof(double) * nn);
    for (int g = 0; g < c.n_clocks; g++) started[g] = ((const uint8_t *)in[17].buf)[g] != 0;
    Py_BEGIN_ALLOW_THREADS
    pass_loop(&c, resume, x, p, fp, xq, pq, values, used, started, &wk, prior_x, prior_p, post_x, post_p, z_all, w_all,
              started_all, relocked, prior_y, post_y, S);
    Py_END_ALLOW_THREADS
    free(mem); free(used); free(started);
    result = Py_None;
    Py_INCREF(result);
done:
    for (int i = 0; i < N_IN; i++) if (in[i].obj) PyBuffer_Release(&in[i]);
    for (int i = 0; i < N_OUT; i++) if (out[i].obj) PyBuffer_Release(&out[i]);
    return result;
}

/* residuals(x, sat, pr, mask, clock, origin, rot, n_states, n_slots, omega, c_mps, out)
 * Each measurement's pseudorange less the range from the trajectory x (E, S) and less its constellation's clock
 * (E, N; NaN in empty slots), the ranges as the pass takes them. */
static PyObject *residuals(PyObject *self, PyObject *args) {
    Py_buffer b[8];
    Pass c;
    int S = 0, slots = 0;
    memset(b, 0, sizeof(b));
    memset(&c, 0, sizeof(c));
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*iiddw*", &b[0], &b[1], &b[2], &b[3], &b[4], &b[5], &b[6], &S, &slots,
                          &c.omega, &c.c_mps, &b[7]))
        return NULL;
    Py_ssize_t N = slots, E = N > 0 ? b[7].len / 8 / N : 0;
    if (S < M || S > MAX_STATES || N < 0 || !check(&b[0], E * S, 8, "x") || !check(&b[1], E * N * 3, 8, "sat") ||
        !check(&b[2], E * N, 8, "pr") || !check(&b[3], E * N, 1, "mask") || !check(&b[4], E * N, 8, "clock") ||
        !check(&b[5], 3, 8, "origin") || !check(&b[6], 9, 8, "rot") || !check(&b[7], E * N, 8, "out")) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "residuals: states out of range");
        goto done;
    }
    c.n_slots = N;
    c.sat = b[1].buf; c.origin = b[5].buf; c.rot = b[6].buf;
    const double *x = b[0].buf, *pr = b[2].buf;
    const uint8_t *mask = b[3].buf;
    const int64_t *clock = b[4].buf;
    double *out = b[7].buf;
    int *used = malloc(sizeof(int) * (N > 0 ? N : 1));
    double *mem = malloc(sizeof(double) * 4 * (N > 0 ? N : 1));
    if (!used || !mem) { free(used); free(mem); PyErr_NoMemory(); goto done; }
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t k = 0; k < E; k++) {
        int n = 0;
        for (Py_ssize_t j = 0; j < N; j++) {
            if (mask[k * N + j]) used[n++] = (int)j;
            else out[k * N + j] = NAN;
        }
        if (!n) continue;
        ranges(&c, x + k * S, k, used, n, mem, mem + N);
        for (int a = 0; a < n; a++) {
            Py_ssize_t slot = k * N + used[a];
            int64_t col = M + (clock[slot] < 0 ? 0 : clock[slot]);
            out[slot] = col < S ? (pr[slot] - mem[a]) - x[k * S + col] : NAN;
        }
    }
    Py_END_ALLOW_THREADS
    free(used);
    free(mem);
    return finish(b, 8, 1);
done:
    return finish(b, 8, 0);
}

/* the horizontal variance (east + north) of A⁻¹, A = wf·F + wb·B (n×n) given by the lower triangles of F and B with
 * their states reordered, the horizontal two last (an element of A is the same number in whichever place it is
 * written): with A so ordered = L Lᵀ, the horizontal block of A⁻¹ is that of L⁻ᵀL⁻¹, which only L's trailing
 * 2×2 block [[a, 0], [b, c]] makes: 1/a² + 1/c² + b²/(a²c²). INFINITY where A is not positive definite. */
INLINE double horizontal_trace_n(const double *f, const double *b, double wf, double wb, const int n, double *work) {
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j++) work[i * n + j] = wf * f[i * n + j] + wb * b[i * n + j];
    if (!cholesky_n(work, n)) return INFINITY;
    double ea = work[(n - 2) * n + n - 2], eb = work[(n - 1) * n + n - 2], ec = work[(n - 1) * n + n - 1];
    double a2 = ea * ea, c2 = ec * ec;
    return (1.0 / a2 + 1.0 / c2) + (eb * eb) / (a2 * c2);
}

static double horizontal_trace(const double *f, const double *b, double wf, double wb, int n, double *work) {
#define C_(k) return horizontal_trace_n(f, b, wf, wb, k, work)
    BY_STATES(C_, n)
#undef C_
}

/* horizontal_trace_n at two weights at once, in lock-step (the same bits): into t[0] (wf0) and t[1] (wf1) */
INLINE void horizontal_trace2_n(const double *f, const double *b, double wf0, double wf1, const int n, double *w0,
                                double *w1, double *t) {
    double wb0 = 1.0 - wf0, wb1 = 1.0 - wf1;
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j++) {
            w0[i * n + j] = wf0 * f[i * n + j] + wb0 * b[i * n + j];
            w1[i * n + j] = wf1 * f[i * n + j] + wb1 * b[i * n + j];
        }
    int ok = cholesky2_n(w0, w1, n);
    double *w[2] = {w0, w1};
    for (int m = 0; m < 2; m++) {
        if (!(ok & (1 << m))) { t[m] = INFINITY; continue; }
        double ea = w[m][(n - 2) * n + n - 2], eb = w[m][(n - 1) * n + n - 2], ec = w[m][(n - 1) * n + n - 1];
        double a2 = ea * ea, c2 = ec * ec;
        t[m] = (1.0 / a2 + 1.0 / c2) + (eb * eb) / (a2 * c2);
    }
}

static void horizontal_trace2(const double *f, const double *b, double wf0, double wf1, int n, double *w0, double *w1,
                              double *t) {
#define C_(k) horizontal_trace2_n(f, b, wf0, wf1, k, w0, w1, t); return
    BY_STATES(C_, n)
#undef C_
}

static int cholesky2(double *a, double *b, int n) {
#define C_(k) return cholesky2_n(a, b, k)
    BY_STATES(C_, n)
#undef C_
}

static void cholesky_inverse2(const double *la, const double *lb, int n, double *lia, double *lib, double *oa, double *ob) {
#define C_(k) cholesky_inverse2_n(la, lb, k, lia, lib, oa, ob); return
    BY_STATES(C_, n)
#undef C_
}

/* the lower triangle of a (n×n) with its states in `order` */
static void reordered(const double *a, int n, const int *order, double *out) {
    for (int i = 0; i < n; i++)
        for (int j = 0; j <= i; j++) out[i * n + j] = a[order[i] * n + order[j]];
}

/* combine(xf, pf, xb, pb, omegas, x, p, omega, yf, yb)
 * Covariance intersection of two estimates (E, S) with covariances (E, S, S) at every epoch: of the weights
 * `omegas` (increasing), the first with the least horizontal variance of (ω P_f⁻¹ + (1 − ω) P_b⁻¹)⁻¹; that matrix is p, and
 * x = p (ω P_f⁻¹ x_f + (1 − ω) P_b⁻¹ x_b). An epoch where a matrix is not positive definite gets NaN. p (E, S, S), or
 * (E, 2, 2): only each matrix's horizontal block kept, or empty (no bytes): nothing kept; x is the same. yf, yb
 * (E, S, S, or empty): P_f⁻¹ and P_b⁻¹ where the passes made them (run_pass's post_y / prior_y), NaN where not: an
 * epoch with both takes them instead of inverting pf and pb. */
static PyObject *combine(PyObject *self, PyObject *args) {
    Py_buffer b[10];
    memset(b, 0, sizeof(b));
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*w*w*w*y*y*", &b[0], &b[1], &b[2], &b[3], &b[4], &b[5], &b[6], &b[7], &b[8], &b[9]))
        return NULL;
    Py_ssize_t E = b[7].len / 8, K = b[4].len / 8;
    int S = E ? (int)(b[0].len / 8 / E) : 0;
    if (E == 0) return finish(b, 10, 1);
    if (S < 2 || S > MAX_STATES) {
        PyErr_SetString(PyExc_ValueError, "combine: states out of range");
        goto done;
    }
    if (!check(&b[0], E * S, 8, "xf") || !check(&b[1], E * S * S, 8, "pf") || !check(&b[2], E * S, 8, "xb") ||
        !check(&b[3], E * S * S, 8, "pb") || !check(&b[5], E * S, 8, "x") ||
        (b[8].len && !check(&b[8], E * S * S, 8, "yf")) || (b[9].len && !check(&b[9], E * S * S, 8, "yb")))
        goto done;
    /* yf, yb: the two estimates' information matrices where known (NaN where not; empty: nowhere) */
    const double *yf = b[8].len ? b[8].buf : NULL, *yb = b[9].len ? b[9].buf : NULL;
    /* p: each epoch's whole matrix (S × S), its horizontal block (2 × 2), or nothing kept (no bytes); x is the same */
    int block = b[6].len == E * S * S * 8 ? S : b[6].len == E * 4 * 8 ? 2 : 0;
    if (block == 0 && !check(&b[6], 0, 8, "p")) goto done;
    size_t nn = (size_t)S * S;
    double *mem = malloc(sizeof(double) * ((8 + K) * nn + 2 * S + K + 1));
    if (!mem) { PyErr_NoMemory(); goto done; }
    const double *xf = b[0].buf, *pf = b[1].buf, *xb = b[2].buf, *pb = b[3].buf, *omegas = b[4].buf;
    double *x_out = b[5].buf, *p_out = b[6].buf, *w_out = b[7].buf;
    double *inf = mem, *inb = inf + nn, *li = inb + nn, *li2 = li + nn, *rf = li2 + nn, *rb = rf + nn, *ordered = rb + nn,
           *scratch = ordered + nn, *factors = scratch + nn, *t = factors + K * nn, *u = t + S, *traces = u + S;
    int order[MAX_STATES];
    for (int i = 0; i < S - 2; i++) order[i] = i + 2;
    order[S - 2] = 0;
    order[S - 1] = 1;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t e = 0; e < E; e++) {
        double *xo = x_out + e * S, *po = block == S ? p_out + e * nn : scratch;
        int ok = 1;
        if (yf && yb && isfinite(yf[e * nn]) && isfinite(yb[e * nn])) { /* the passes' own: not inverted again */
            memcpy(inf, yf + e * nn, sizeof(double) * nn);
            memcpy(inb, yb + e * nn, sizeof(double) * nn);
        } else {
            memcpy(inf, pf + e * nn, sizeof(double) * nn);
            memcpy(inb, pb + e * nn, sizeof(double) * nn);
            if (cholesky2(inf, inb, S) == 3) cholesky_inverse2(inf, inb, S, li, li2, inf, inb);
            else ok = 0;
        }
        if (ok) {
            reordered(inf, S, order, rf);
            reordered(inb, S, order, rb);
        }
        /* the trace is convex in ω (X ↦ X⁻¹ is matrix-convex, A(ω) affine): the first of the least on the grid is
         * where it first stops falling, found by halving (trace memoised per ω, and the factor it came from) */
        double best = INFINITY, omega = NAN;
        Py_ssize_t lo = 0, hi = K - 1;
        if (ok) {
            for (Py_ssize_t k = 0; k < K; k++) traces[k] = NAN;
            while (lo < hi) {
                Py_ssize_t mid = (lo + hi) / 2;
                if (isnan(traces[mid]) && isnan(traces[mid + 1]))
                    horizontal_trace2(rf, rb, omegas[mid], omegas[mid + 1], S, factors + mid * nn, factors + (mid + 1) * nn,
                                      traces + mid);
                else
                    for (Py_ssize_t k = mid; k <= mid + 1; k++)
                        if (isnan(traces[k])) traces[k] = horizontal_trace(rf, rb, omegas[k], 1.0 - omegas[k], S, factors + k * nn);
                if (traces[mid] <= traces[mid + 1]) hi = mid; else lo = mid + 1;
            }
            if (isnan(traces[lo])) traces[lo] = horizontal_trace(rf, rb, omegas[lo], 1.0 - omegas[lo], S, factors + lo * nn);
            best = traces[lo];
            omega = omegas[lo];
        }
        if (ok && isfinite(best)) {
            /* x = A⁻¹ (ω P_f⁻¹ x_f + (1 − ω) P_b⁻¹ x_b) solved with the factor of A (states reordered) the trace came from */
            const double *l = factors + lo * nn;
            double wf = omega, wb = 1.0 - omega;
            for (int i = 0; i < S; i++) {
                double sf = 0.0, sb = 0.0;
                for (int j = 0; j < S; j++) { sf += inf[i * S + j] * xf[e * S + j]; sb += inb[i * S + j] * xb[e * S + j]; }
                t[i] = wf * sf + wb * sb;
            }
            for (int i = 0; i < S; i++) u[i] = t[order[i]];
            cholesky_solve(l, S, u);
            for (int i = 0; i < S; i++) xo[order[i]] = u[i];
            if (block == S) { /* A⁻¹ from the same factor, back in the states' order */
                cholesky_inverse(l, S, li, ordered);
                for (int i = 0; i < S; i++)
                    for (int j = 0; j < S; j++) po[order[i] * S + order[j]] = ordered[i * S + j];
            } else if (block == 2) { /* its horizontal block: cholesky_inverse's steps on the factor's last two rows */
                double la = 1.0 / l[(S - 2) * S + S - 2], lc = 1.0 / l[(S - 1) * S + S - 1];
                double s = 0.0;
                s -= l[(S - 1) * S + S - 2] * la;
                double lb = s * lc;
                double *h = p_out + e * 4;
                h[0] = (0.0 + la * la) + lb * lb;
                h[1] = h[2] = 0.0 + lc * lb;
                h[3] = 0.0 + lc * lc;
            }
        } else ok = 0;
        if (!ok) {
            for (int i = 0; i < S; i++) xo[i] = NAN;
            if (block == S) for (size_t i = 0; i < nn; i++) po[i] = NAN;
            if (block == 2) for (int i = 0; i < 4; i++) p_out[e * 4 + i] = NAN;
            omega = NAN;
        }
        w_out[e] = omega;
    }
    Py_END_ALLOW_THREADS
    free(mem);
    return finish(b, 10, 1);
done:
    return finish(b, 10, 0);
}

static PyMethodDef methods[] = {
    {"run_pass", run_pass, METH_VARARGS, "One pass of the trajectory filter (see trajectory_pass_twin.run_pass)."},
    {"residuals", residuals, METH_VARARGS, "Post-fit residuals (see trajectory_pass_twin.residuals)."},
    {"combine", combine, METH_VARARGS, "Covariance intersection per epoch (see trajectory_pass_twin.combine)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_trajectory_kernel",
                                    "Compiled twin of the trajectory filter's pass.", -1, methods};

PyMODINIT_FUNC PyInit__trajectory_kernel(void) { return PyModule_Create(&module); }
