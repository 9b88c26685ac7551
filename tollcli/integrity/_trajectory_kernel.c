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
 * Why this file is long: the pass's four steps (clocks started, prediction, robust update, widening), the
 * combination, the small dense algebra they need (Cholesky, its solve and inverse), and the argument checking of
 * two entry points.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define M 6          /* motion states before the clocks (trajectory_filter.MOTION_STATES) */
#define N_NOISE 11   /* MotionNoise's fields, in trajectory_filter.NOISE_FIELDS order */
#define MAX_STATES 64

typedef struct {
    Py_ssize_t n_epochs, n_slots;
    int n_states, n_clocks, odometry, direction, iterations, lost_min, keep_prior, keep_post;
    double omega, c_mps, cauchy, relinearise;
    const double *t, *sat, *pr, *sigma2, *robust2, *speed, *yaw, *forward, *left, *origin, *rot, *noise;
    const uint8_t *mask;
    const int64_t *clock;
} Pass;

/* noise fields (trajectory_filter.NOISE_FIELDS) */
enum { ALONG, SHARE, POSITION, NO_ODO, YAW, HEADING, UP, CLOCK, DRIFT, ACCEL, GYRO_BIAS };

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
static int cholesky(double *a, int n) {
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
static void cholesky_solve(const double *l, int n, double *b) {
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
static void cholesky_inverse(const double *l, int n, double *li, double *out) {
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

/* p := F p Fᵀ for F = I + Σ v·e_i e_jᵀ over the entries (i, j, v), then symmetrised; fp, work: n×n */
static void transition(double *p, int n, const int *ei, const int *ej, const double *ev, int ne, double *fp) {
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

/* the state dt_s later (direction -1: earlier), through the interval ending at epoch `interval` */
static void predict(const Pass *c, double *x, double *p, double dt, Py_ssize_t interval, double *fp) {
    int n = c->n_states, drift = M - 1, ne = 0, ei[MAX_STATES + 8], ej[MAX_STATES + 8];
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
            double de = fw * sn - lf * cs, dn = fw * cs + lf * sn;
            x[0] += dir * de;
            x[1] += dir * dn;
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
        } else { /* an interval without odometry: the position wanders, the heading too */
            q[0] = nz[NO_ODO] * dt;
            q[1] = nz[NO_ODO] * dt;
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
    x[0] += x[3] * s;
    x[1] += x[4] * s;
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
    double *info, *a, *li, *x, *b, *rng, *u, *z, *w;
} Work;

/* the robust (Cauchy, iteratively reweighted) update of epoch k from the prior (xp, pp), in information form;
 * writes x, p, z, w; 0 where a matrix was not positive definite (x, p then the prior's, z NaN, w 0) */
static int update(const Pass *c, const double *xp, const double *pp, Py_ssize_t k, const int *used, int n, double *x_out,
                  double *p_out, Work *wk) {
    int ns = c->n_states;
    size_t nn = (size_t)ns * ns;
    double *x = wk->x;
    memcpy(wk->info, pp, sizeof(double) * nn);
    if (!cholesky(wk->info, ns)) goto failed;
    cholesky_inverse(wk->info, ns, wk->li, wk->info);
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
        if (!cholesky(wk->a, ns)) goto failed;
        cholesky_solve(wk->a, ns, wk->b);
        double change = 0.0;
        for (int a = 0; a < ns; a++) {
            double xn = xp[a] + wk->b[a];
            if (a < 3 && fabs(xn - x[a]) > change) change = fabs(xn - x[a]);
            x[a] = xn;
        }
        if (change < c->relinearise) break;
    }
    cholesky_inverse(wk->a, ns, wk->li, p_out);
    memcpy(x_out, x, sizeof(double) * ns);
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

#define N_IN 17
#define N_OUT 8

/* run_pass(t, sat, pr, mask, clock, sigma2, robust2, speed, yaw, forward, left, origin, rot, noise, start_x, start_p,
 *          start_started, prior_x, prior_p, post_x, post_p, z, w, started, relocked,
 *          direction, odometry, n_clocks, iterations, lost_min, keep_prior, keep_post, resume, omega, c_mps, cauchy,
 *          relinearise)
 * keep_prior / keep_post 0: the priors / posteriors are not kept (their arrays empty; a pass's other half is what the
 * combination reads: the forward posteriors, the backward priors).
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
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*y*y*y*y*y*y*y*y*y*y*w*w*w*w*w*w*w*w*iiiiiiiidddd", &in[0], &in[1], &in[2],
                          &in[3], &in[4], &in[5], &in[6], &in[7], &in[8], &in[9], &in[10], &in[11], &in[12], &in[13],
                          &in[14], &in[15], &in[16], &out[0], &out[1], &out[2], &out[3], &out[4], &out[5], &out[6], &out[7],
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
        !check(&in[10], E, 8, "left") || !check(&in[11], 3, 8, "origin") || !check(&in[12], 9, 8, "rot") ||
        !check(&in[13], N_NOISE, 8, "noise") || !check(&in[14], S, 8, "start_x") || !check(&in[15], S * S, 8, "start_p") || !check(&in[16], c.n_clocks, 1, "start_started") ||
        !check(&out[0], c.keep_prior ? E * S : 0, 8, "prior_x") || !check(&out[1], c.keep_prior ? E * S * S : 0, 8, "prior_p") ||
        !check(&out[2], c.keep_post ? E * S : 0, 8, "post_x") || !check(&out[3], c.keep_post ? E * S * S : 0, 8, "post_p") || !check(&out[4], E * N, 8, "z") ||
        !check(&out[5], E * N, 8, "w") || !check(&out[6], E * c.n_clocks, 1, "started") ||
        !check(&out[7], E, 1, "relocked"))
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
    c.left = in[10].buf; c.origin = in[11].buf; c.rot = in[12].buf; c.noise = in[13].buf;
    double *prior_x = out[0].buf, *prior_p = out[1].buf, *post_x = out[2].buf, *post_p = out[3].buf;
    double *z_all = out[4].buf, *w_all = out[5].buf;
    uint8_t *started_all = out[6].buf, *relocked = out[7].buf;
    size_t nn = (size_t)S * S, slots = N > 0 ? (size_t)N : 1;
    double *mem = malloc(sizeof(double) * (7 * nn + 3 * S + 8 * slots));
    int *used = malloc(sizeof(int) * slots);
    uint8_t *started = calloc(c.n_clocks + 1, 1);
    if (!mem || !used || !started) {
        free(mem); free(used); free(started);
        PyErr_NoMemory();
        goto done;
    }
    double *x = mem, *p = x + S, *fp = p + nn, *xq = fp + nn, *pq = xq + S, *values = pq + nn;
    Work wk = {values + slots, 0, 0, 0, 0, 0, 0, 0, 0};
    wk.a = wk.info + nn; wk.li = wk.a + nn; wk.x = wk.li + nn; wk.b = wk.x + S;
    wk.rng = wk.b + S; wk.u = wk.rng + slots; wk.z = wk.u + 3 * slots; wk.w = wk.z + slots;
    memcpy(x, in[14].buf, sizeof(double) * S);
    memcpy(p, in[15].buf, sizeof(double) * nn);
    for (int g = 0; g < c.n_clocks; g++) started[g] = ((const uint8_t *)in[16].buf)[g] != 0;
    Py_BEGIN_ALLOW_THREADS
    Py_ssize_t previous = -1;
    for (Py_ssize_t step = 0; step < E; step++) {
        Py_ssize_t k = c.direction > 0 ? step : E - 1 - step;
        if (resume && step == 0) { /* the state given is this epoch's posterior: go on from it */
            previous = k;
            continue;
        }
        if (previous >= 0) predict(&c, x, p, fabs(c.t[k] - c.t[previous]), k > previous ? k : previous, fp);
        int n = 0;
        for (Py_ssize_t j = 0; j < N; j++) if (c.mask[k * N + j]) used[n++] = (int)j;
        if (n) start_clocks(&c, x, p, started, k, used, n, wk.rng, wk.u, values);
        if (c.keep_prior) {
            memcpy(prior_x + k * S, x, sizeof(double) * S);
            memcpy(prior_p + k * nn, p, sizeof(double) * nn);
        }
        memcpy(started_all + k * c.n_clocks, started, c.n_clocks);
        if (n) {
            int ok = update(&c, x, p, k, used, n, xq, pq, &wk);
            int low = 0;
            for (int i = 0; i < n; i++) low += wk.w[i] < 0.5;
            if (ok && n >= c.lost_min && 2 * low > n) { /* the pass has lost the vehicle */
                widen(p, S, c.odometry);
                if (c.keep_prior) memcpy(prior_p + k * nn, p, sizeof(double) * nn);
                relocked[k] = 1;
                update(&c, x, p, k, used, n, xq, pq, &wk);
            }
            memcpy(x, xq, sizeof(double) * S);
            memcpy(p, pq, sizeof(double) * nn);
            for (int i = 0; i < n; i++) { z_all[k * N + used[i]] = wk.z[i]; w_all[k * N + used[i]] = wk.w[i]; }
        }
        if (c.keep_post) {
            memcpy(post_x + k * S, x, sizeof(double) * S);
            memcpy(post_p + k * nn, p, sizeof(double) * nn);
        }
        previous = k;
    }
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

/* the horizontal variance (east + north) of A⁻¹, A (n×n) with its states in `order` (the horizontal two last):
 * with A's rows and columns so ordered = L Lᵀ, the horizontal block of A⁻¹ is that of L⁻ᵀL⁻¹, which only L's trailing
 * 2×2 block [[a, 0], [b, c]] makes: 1/a² + 1/c² + b²/(a²c²). INFINITY where A is not positive definite. */
static double horizontal_trace(const double *a, int n, const int *order, double *work) {
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) work[i * n + j] = a[order[i] * n + order[j]];
    if (!cholesky(work, n)) return INFINITY;
    double ea = work[(n - 2) * n + n - 2], eb = work[(n - 1) * n + n - 2], ec = work[(n - 1) * n + n - 1];
    double a2 = ea * ea, c2 = ec * ec;
    return (1.0 / a2 + 1.0 / c2) + (eb * eb) / (a2 * c2);
}

/* combine(xf, pf, xb, pb, omegas, x, p, omega)
 * Covariance intersection of two estimates (E, S) with covariances (E, S, S) at every epoch: of the weights
 * `omegas` (increasing), the first with the least horizontal variance of (ω P_f⁻¹ + (1 − ω) P_b⁻¹)⁻¹; that matrix is p, and
 * x = p (ω P_f⁻¹ x_f + (1 − ω) P_b⁻¹ x_b). An epoch where a matrix is not positive definite gets NaN. */
static PyObject *combine(PyObject *self, PyObject *args) {
    Py_buffer b[8];
    memset(b, 0, sizeof(b));
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*w*w*w*", &b[0], &b[1], &b[2], &b[3], &b[4], &b[5], &b[6], &b[7])) return NULL;
    Py_ssize_t E = b[7].len / 8, K = b[4].len / 8;
    int S = E ? (int)(b[0].len / 8 / E) : 0;
    if (E == 0) return finish(b, 8, 1);
    if (S < 2 || S > MAX_STATES) {
        PyErr_SetString(PyExc_ValueError, "combine: states out of range");
        goto done;
    }
    if (!check(&b[0], E * S, 8, "xf") || !check(&b[1], E * S * S, 8, "pf") || !check(&b[2], E * S, 8, "xb") ||
        !check(&b[3], E * S * S, 8, "pb") || !check(&b[5], E * S, 8, "x") || !check(&b[6], E * S * S, 8, "p"))
        goto done;
    size_t nn = (size_t)S * S;
    double *mem = malloc(sizeof(double) * (5 * nn + 2 * S + K + 1));
    if (!mem) { PyErr_NoMemory(); goto done; }
    const double *xf = b[0].buf, *pf = b[1].buf, *xb = b[2].buf, *pb = b[3].buf, *omegas = b[4].buf;
    double *x_out = b[5].buf, *p_out = b[6].buf, *w_out = b[7].buf;
    double *inf = mem, *inb = inf + nn, *a = inb + nn, *work = a + nn, *li = work + nn, *t = li + nn, *u = t + S, *traces = u + S;
    int order[MAX_STATES];
    for (int i = 0; i < S - 2; i++) order[i] = i + 2;
    order[S - 2] = 0;
    order[S - 1] = 1;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t e = 0; e < E; e++) {
        double *xo = x_out + e * S, *po = p_out + e * nn;
        int ok = 1;
        memcpy(inf, pf + e * nn, sizeof(double) * nn);
        memcpy(inb, pb + e * nn, sizeof(double) * nn);
        if (cholesky(inf, S) && cholesky(inb, S)) {
            cholesky_inverse(inf, S, li, inf);
            cholesky_inverse(inb, S, li, inb);
        } else ok = 0;
        /* the trace is convex in ω (X ↦ X⁻¹ is matrix-convex, A(ω) affine): the first of the least on the grid is
         * where it first stops falling, found by halving (trace memoised per ω) */
        double best = INFINITY, omega = NAN;
        if (ok) {
            Py_ssize_t lo = 0, hi = K - 1;
            for (Py_ssize_t k = 0; k < K; k++) traces[k] = NAN;
            while (lo < hi) {
                Py_ssize_t mid = (lo + hi) / 2;
                for (Py_ssize_t k = mid; k <= mid + 1; k++)
                    if (isnan(traces[k])) {
                        double wf = omegas[k], wb = 1.0 - omegas[k];
                        for (size_t i = 0; i < nn; i++) a[i] = wf * inf[i] + wb * inb[i];
                        traces[k] = horizontal_trace(a, S, order, work);
                    }
                if (traces[mid] <= traces[mid + 1]) hi = mid; else lo = mid + 1;
            }
            if (isnan(traces[lo])) {
                double wf = omegas[lo], wb = 1.0 - omegas[lo];
                for (size_t i = 0; i < nn; i++) a[i] = wf * inf[i] + wb * inb[i];
                traces[lo] = horizontal_trace(a, S, order, work);
            }
            best = traces[lo];
            omega = omegas[lo];
        }
        if (ok && isfinite(best)) {
            double wf = omega, wb = 1.0 - omega;
            for (size_t i = 0; i < nn; i++) a[i] = wf * inf[i] + wb * inb[i];
            ok = cholesky(a, S);
            if (ok) {
                cholesky_inverse(a, S, li, po);
                for (int i = 0; i < S; i++) {
                    double sf = 0.0, sb = 0.0;
                    for (int j = 0; j < S; j++) { sf += inf[i * S + j] * xf[e * S + j]; sb += inb[i * S + j] * xb[e * S + j]; }
                    t[i] = wf * sf + wb * sb;
                }
                for (int i = 0; i < S; i++) {
                    double s = 0.0;
                    for (int j = 0; j < S; j++) s += po[i * S + j] * t[j];
                    u[i] = s;
                }
                memcpy(xo, u, sizeof(double) * S);
            }
        } else ok = 0;
        if (!ok) {
            for (int i = 0; i < S; i++) xo[i] = NAN;
            for (size_t i = 0; i < nn; i++) po[i] = NAN;
            omega = NAN;
        }
        w_out[e] = omega;
    }
    Py_END_ALLOW_THREADS
    free(mem);
    return finish(b, 8, 1);
done:
    return finish(b, 8, 0);
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
