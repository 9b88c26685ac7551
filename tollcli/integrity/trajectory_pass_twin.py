"""One pass of the trajectory filter, and the combination of two passes, in plain Python: the reference, and the
fallback where the compiled twin (``_trajectory_kernel.c``) was not built.

The two compute the same bits: each step below is the C file's, with every sum in the same order and every
product and quotient grouped as there (Python floats are IEEE doubles; ``math.sqrt`` is exact, ``math.sin`` and
``math.cos`` are the C library's). So an invoice does not depend on whether the machine had a C compiler:
``tests/test_trajectory_kernel.py`` compares them bit for bit on real and simulated drives.

This version is about a hundred times slower than the compiled one (scalar Python over 10–16 states): it is what
an install without a C compiler runs, and what the test checks the kernel against on short stretches.

Arguments are those of the kernel (:func:`run_pass`, :func:`combine`); the matrices are row-major flat arrays.

Why this file is long: it is the C file's steps one for one (prediction, clocks started, robust update, widening, the
combination, their small dense algebra), kept together so that each can be read beside its compiled twin.
"""

from __future__ import annotations

import math

import numpy as np

#: motion states before the clocks (``trajectory_filter.MOTION_STATES``)
M = 6
#: the Earth's mean radius (m): the tangent plane's fall below the road, (e² + n²) / 2R (:func:`_follow_surface`)
EARTH_RADIUS_M = 6_371_000.0
ALONG, SHARE, POSITION, GAP_SPEED, YAW, HEADING, UP, CLOCK, DRIFT, ACCEL, GYRO_BIAS = range(11)


def _ranges(c, x, k, used):
    """Ranges (m) and ENU unit vectors from ``x[:3]`` to epoch ``k``'s used satellites."""
    r, o = c["rot"], c["origin"]
    pos = [o[i] + ((r[i] * x[0] + r[3 + i] * x[1]) + r[6 + i] * x[2]) for i in range(3)]
    sat = c["sat"]
    rng, u = [], []
    base = k * c["n_slots"]
    omega, c_mps = c["omega"], c["c_mps"]
    for j in used:
        s0, s1, s2 = sat[(base + j) * 3], sat[(base + j) * 3 + 1], sat[(base + j) * 3 + 2]
        dx, dy, dz = s0 - pos[0], s1 - pos[1], s2 - pos[2]
        rough = math.sqrt((dx * dx + dy * dy) + dz * dz)
        theta = omega * rough / c_mps  # the Earth's turn during the flight (≲ 1e-5 rad): its Taylor series
        t2 = theta * theta
        ct, st = 1.0 - t2 / 2.0 * (1.0 - t2 / 12.0), theta * (1.0 - t2 / 6.0 * (1.0 - t2 / 20.0))
        v0 = (ct * s0 + st * s1) - pos[0]
        v1 = ((-st) * s0 + ct * s1) - pos[1]
        v2 = s2 - pos[2]
        d = math.sqrt((v0 * v0 + v1 * v1) + v2 * v2)
        e0, e1, e2 = v0 / d, v1 / d, v2 / d
        rng.append(d)
        u.append([(e0 * r[b * 3] + e1 * r[b * 3 + 1]) + e2 * r[b * 3 + 2] for b in range(3)])
    return rng, u


def _cholesky(a, n):
    """``a`` (flat n×n) = L Lᵀ, L over its lower triangle; False where not positive definite."""
    for j in range(n):
        d = a[j * n + j]
        for k in range(j):
            d -= a[j * n + k] * a[j * n + k]
        if not (d > 0.0) or not math.isfinite(d):
            return False
        d = math.sqrt(d)
        a[j * n + j] = d
        r = 1.0 / d
        for i in range(j + 1, n):
            s = a[i * n + j]
            for k in range(j):
                s -= a[i * n + k] * a[j * n + k]
            a[i * n + j] = s * r
    return True


def _cholesky_solve(lo, n, b):
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= lo[i * n + k] * b[k]
        b[i] = s / lo[i * n + i]
    for i in range(n - 1, -1, -1):
        s = b[i]
        for k in range(i + 1, n):
            s -= lo[k * n + i] * b[k]
        b[i] = s / lo[i * n + i]


def _cholesky_inverse(lo, n):
    li = [0.0] * (n * n)
    for j in range(n):
        li[j * n + j] = 1.0 / lo[j * n + j]
    for j in range(n):
        for i in range(j + 1, n):
            s = 0.0
            for k in range(j, i):
                s -= lo[i * n + k] * li[k * n + j]
            li[i * n + j] = s * li[i * n + i]
    out = [0.0] * (n * n)
    for i in range(n):
        for j in range(i + 1):
            s = 0.0
            for k in range(i, n):
                s += li[k * n + i] * li[k * n + j]
            out[i * n + j] = s
            out[j * n + i] = s
    return out


def _transition(p, n, entries):
    """F p Fᵀ for F = I + Σ v e_i e_jᵀ over ``entries`` (i, j, v), symmetrised."""
    fp = list(p)
    for i, j, v in entries:
        for b in range(n):
            fp[i * n + b] += v * p[j * n + b]
    out = list(fp)
    for i, j, v in entries:
        for a in range(n):
            out[a * n + i] += v * fp[a * n + j]
    for a in range(n):
        for b in range(a):
            s = (out[a * n + b] + out[b * n + a]) * 0.5
            out[a * n + b] = s
            out[b * n + a] = s
    return out


def _follow_surface(x, e0, n0):
    """The height falls as the road leaves the tangent plane (the kernel's ``follow_surface``)."""
    x[2] -= ((x[0] * x[0] + x[1] * x[1]) - (e0 * e0 + n0 * n0)) / (2.0 * EARTH_RADIUS_M)


def _predict(c, x, p, dt, interval):
    n, drift, nz = c["n_states"], M - 1, c["noise"]
    d = float(c["direction"])
    s = d * dt
    entries = []
    for g in range(M, n):
        x[g] += x[drift] * s
        entries.append((g, drift, s))
    if c["odometry"]:
        v, w, fw, lf = c["speed"][interval], c["yaw"][interval], c["forward"][interval], c["left"][interval]
        q = [0.0] * n
        if math.isfinite(v) and math.isfinite(w) and math.isfinite(fw) and math.isfinite(lf):
            x[3] -= (w - x[4]) * s
            entries.append((3, 4, s))
            if c["direction"] < 0:
                psi, dpsi = x[3], s
            else:
                psi, dpsi = x[3] + (w - x[4]) * s, 0.0
            sn, cs = math.sin(psi), math.cos(psi)
            de, dn = fw * sn - lf * cs, fw * cs + lf * sn
            e0, n0 = x[0], x[1]
            x[0] += d * de
            x[1] += d * dn
            _follow_surface(x, e0, n0)
            entries += [(0, 3, d * dn), (1, 3, -(d * de)), (0, 4, d * dn * dpsi), (1, 4, -(d * de) * dpsi)]
            sv = nz[ALONG] + nz[SHARE] * abs(v)
            lat = 0.5 * nz[YAW] * dt * abs(fw)
            ae, an, ay = sv * dt * sn, sv * dt * cs, nz[YAW] * dt
            q[0] = (ae * ae + nz[POSITION] * dt) + lat * lat
            q[1] = (an * an + nz[POSITION] * dt) + lat * lat
            q[3] = ay * ay + nz[HEADING] * dt
        else:  # as far as the vehicle may have gone since the last interval with odometry (trajectory_filter.wander_m2)
            q[0] = c["wander"][interval]
            q[1] = c["wander"][interval]
            q[3] = 0.1 * dt
        q[2] = nz[UP] * dt
        q[4] = nz[GYRO_BIAS] * dt
        for g in range(M, n):
            q[g] = nz[CLOCK] * dt
        q[drift] = nz[DRIFT] * dt
        p = _transition(p, n, entries)
        for a in range(n):
            p[a * n + a] += q[a]
        return p
    e0, n0 = x[0], x[1]
    x[0] += x[3] * s
    x[1] += x[4] * s
    _follow_surface(x, e0, n0)
    entries += [(0, 3, s), (1, 4, s)]
    p = _transition(p, n, entries)
    qa = nz[ACCEL]
    for axis in range(2):
        ps, vl = axis, axis + 3
        cross = qa * s * dt / 2.0
        p[ps * n + ps] += qa * dt * dt * dt / 3.0
        p[ps * n + vl] += cross
        p[vl * n + ps] += cross
        p[vl * n + vl] += qa * dt
    p[2 * n + 2] += nz[UP] * dt
    for g in range(M, n):
        p[g * n + g] += nz[CLOCK] * dt
    p[drift * n + drift] += nz[DRIFT] * dt
    return p


def _start_clocks(c, x, p, started, k, used):
    clock, pr, base, ns = c["clock"], c["pr"], k * c["n_slots"], c["n_states"]
    if all(started[clock[base + j]] for j in used):
        return
    rng, _ = _ranges(c, x, k, used)
    for g in range(c["n_clocks"]):
        if started[g]:
            continue
        values = sorted(pr[base + j] - rng[a] for a, j in enumerate(used) if clock[base + j] == g)
        if not values:
            continue
        h = len(values) // 2
        col = M + g
        x[col] = values[h] if len(values) % 2 else (values[h - 1] + values[h]) / 2.0
        for a in range(ns):
            p[col * ns + a] = 0.0
            p[a * ns + col] = 0.0
        p[col * ns + col] = ((10000.0 + p[0]) + p[ns + 1]) + p[2 * ns + 2]
        started[g] = 1


def _update(c, xp, pp, k, used):
    """The robust update of epoch ``k``: (ok, x, p, z, w, the prior's information matrix, the posterior's) as the
    kernel's ``update`` (an information matrix None where not made)."""
    ns, n = c["n_states"], len(used)
    base, clock, pr, robust2, sigma2, cauchy = k * c["n_slots"], c["clock"], c["pr"], c["robust2"], c["sigma2"], c["cauchy"]
    info = list(pp)
    if not _cholesky(info, ns):
        return False, list(xp), list(pp), [math.nan] * n, [0.0] * n, None, None
    info = _cholesky_inverse(info, ns)
    x = list(xp)
    a_mat = info
    z, w = [0.0] * n, [0.0] * n
    for _ in range(c["iterations"]):
        rng, u = _ranges(c, x, k, used)
        a_mat = list(info)
        b = [0.0] * ns
        for i, j in enumerate(used):
            slot = base + j
            idx = (0, 1, 2, M + clock[slot])
            h = (-u[i][0], -u[i][1], -u[i][2], 1.0)
            hd = 0.0
            sd = 0.0
            for a in range(4):
                hd += h[a] * (xp[idx[a]] - x[idx[a]])
            for a in range(4):
                t = 0.0
                row = idx[a] * ns
                for bb in range(4):
                    t += pp[row + idx[bb]] * h[bb]
                sd += h[a] * t
            r = ((pr[slot] - rng[i]) - x[idx[3]]) - hd
            zi = r / math.sqrt(sd + robust2[slot])
            qz = zi / cauchy
            wi = 1.0 / (1.0 + qz * qz)
            wd = wi / sigma2[slot]
            z[i], w[i] = zi, wi
            for a in range(4):
                wh = wd * h[a]
                row = idx[a] * ns
                for bb in range(4):
                    a_mat[row + idx[bb]] += wh * h[bb]
                b[idx[a]] += (wd * r) * h[a]
        a_info = list(a_mat)
        if not _cholesky(a_mat, ns):
            return False, list(xp), list(pp), [math.nan] * n, [0.0] * n, info, None
        _cholesky_solve(a_mat, ns, b)
        change = 0.0
        for a in range(ns):
            xn = xp[a] + b[a]
            if a < 3 and abs(xn - x[a]) > change:
                change = abs(xn - x[a])
            x[a] = xn
        if change < c["relinearise"]:
            break
    return True, x, _cholesky_inverse(a_mat, ns), z, w, info, a_info


def _widen(p, ns, odometry):
    for a in range(3):
        p[a * ns + a] += 10000.0
    for g in range(M, ns):
        p[g * ns + g] += 10000.0
    p[3 * ns + 3] += 0.5 * 0.5 if odometry else 10.0 * 10.0
    p[4 * ns + 4] += 0.01 * 0.01 if odometry else 10.0 * 10.0


def run_pass(t, sat, pr, mask, clock, sigma2, robust2, speed, yaw, forward, left, wander, origin, rot, noise, start_x, start_p,
             start_started, prior_x, prior_p, post_x, post_p, z_all, w_all, started_all, relocked, prior_y, post_y,
             direction, odometry, n_clocks, iterations, lost_min, keep_prior, keep_post, resume, omega, c_mps, cauchy,
             relinearise):  # fmt: skip
    """The kernel's ``run_pass``: the inputs as contiguous arrays (``sat`` (E, N, 3), ``mask`` uint8, ``clock``
    int64), the outputs filled in place. ``start_started``: the clock groups started before the first epoch visited;
    ``resume``: the start is the state after the first epoch visited, which is not visited again."""
    n_epochs, n_slots = pr.shape
    ns = M + n_clocks
    c = dict(n_slots=n_slots, n_states=ns, n_clocks=n_clocks, direction=direction, odometry=odometry,
             iterations=iterations, relinearise=relinearise, omega=omega, c_mps=c_mps, cauchy=cauchy, sat=sat.ravel().tolist(),
             pr=pr.ravel().tolist(), clock=clock.ravel().tolist(), sigma2=sigma2.ravel().tolist(),
             robust2=robust2.ravel().tolist(), speed=speed.tolist(), yaw=yaw.tolist(), forward=forward.tolist(),
             left=left.tolist(), wander=wander.tolist(), origin=origin.tolist(), rot=rot.ravel().tolist(), noise=noise.tolist())  # fmt: skip
    tt = t.tolist()
    x, p = start_x.tolist(), start_p.ravel().tolist()
    started = [1 if v else 0 for v in start_started.tolist()]
    prior_p2 = prior_p.reshape(n_epochs, ns * ns) if keep_prior else None
    post_p2 = post_p.reshape(n_epochs, ns * ns) if keep_post else None
    prior_y2 = prior_y.reshape(n_epochs, ns * ns) if keep_prior else None
    post_y2 = post_y.reshape(n_epochs, ns * ns) if keep_post else None
    previous = -1
    for step in range(n_epochs):
        k = step if direction > 0 else n_epochs - 1 - step
        if resume and step == 0:  # the state given is this epoch's posterior: go on from it
            previous = k
            continue
        if previous >= 0:
            p = _predict(c, x, p, abs(tt[k] - tt[previous]), max(k, previous))
        used = np.flatnonzero(mask[k]).tolist()
        if used:
            _start_clocks(c, x, p, started, k, used)
        if keep_prior:
            prior_x[k], prior_p2[k] = x, p
        started_all[k] = started
        info = a_info = None
        if used:
            ok, xq, pq, z, w, info, a_info = _update(c, x, p, k, used)
            low = sum(1 for v in w if v < 0.5)
            if ok and len(used) >= lost_min and 2 * low > len(used):
                _widen(p, ns, odometry)
                if keep_prior:
                    prior_p2[k] = p
                relocked[k] = 1
                _, xq, pq, z, w, info, a_info = _update(c, x, p, k, used)
            x, p = xq, pq
            z_all[k, used], w_all[k, used] = z, w
        if keep_prior:
            prior_y2[k] = math.nan if info is None else info
        if keep_post:
            post_x[k], post_p2[k] = x, p
            post_y2[k] = math.nan if a_info is None else a_info
        previous = k


def _horizontal_trace(a, n, order):
    """East + north variance of ``a``⁻¹ (the kernel's ``horizontal_trace``), and the Cholesky factor of ``a`` with its
    states in ``order`` it came from; inf (and None) where not positive definite."""
    work = [a[order[i] * n + order[j]] for i in range(n) for j in range(n)]
    if not _cholesky(work, n):
        return math.inf, None
    ea, eb, ec = work[(n - 2) * n + n - 2], work[(n - 1) * n + n - 2], work[(n - 1) * n + n - 1]
    a2, c2 = ea * ea, ec * ec
    return (1.0 / a2 + 1.0 / c2) + (eb * eb) / (a2 * c2), work


def combine(xf, pf, xb, pb, omegas, x_out, p_out, w_out, yf, yb):
    """The kernel's ``combine``: covariance intersection of (xf, pf) and (xb, pb) at every epoch, into ``x_out``,
    ``p_out`` ((E, S, S); (E, 2, 2): each matrix's horizontal block; empty: not kept) and ``w_out`` (ω; NaN where a
    matrix is not positive definite). x is solved, and p inverted, from the factor of the weight's matrix (states
    reordered, the horizontal two last) its trace came from. ``yf``, ``yb`` (E, S, S; or empty): P_f⁻¹ and P_b⁻¹ where
    known (NaN where not), taken instead of inverting."""
    n_epochs, ns = xf.shape
    nn = ns * ns
    order = list(range(2, ns)) + [0, 1]
    grid = omegas.tolist()
    pf2, pb2 = pf.reshape(n_epochs, nn), pb.reshape(n_epochs, nn)
    block = ns if p_out.size == n_epochs * nn else 2 if p_out.size else 0
    po2 = p_out.reshape(n_epochs, block * block)
    yf2, yb2 = (y.reshape(n_epochs, nn) if y.size else None for y in (yf, yb))
    for e in range(n_epochs):
        best, omega, factors = math.inf, math.nan, {}
        if yf2 is not None and yb2 is not None and math.isfinite(yf2[e, 0]) and math.isfinite(yb2[e, 0]):
            ok, inf, inb = True, yf2[e].tolist(), yb2[e].tolist()
        else:
            inf, inb = pf2[e].tolist(), pb2[e].tolist()
            ok = _cholesky(inf, ns) and _cholesky(inb, ns)
            if ok:
                inf, inb = _cholesky_inverse(inf, ns), _cholesky_inverse(inb, ns)
        if ok:
            traces = [math.nan] * len(grid)

            def trace(k):
                if math.isnan(traces[k]):
                    wf, wb = grid[k], 1.0 - grid[k]
                    traces[k], factors[k] = _horizontal_trace([wf * inf[i] + wb * inb[i] for i in range(nn)], ns, order)
                return traces[k]

            lo, hi = 0, len(grid) - 1  # the first of the least of a convex sequence: where it first stops falling
            while lo < hi:
                mid = (lo + hi) // 2
                below, above = trace(mid), trace(mid + 1)
                if below <= above:
                    hi = mid
                else:
                    lo = mid + 1
            best, omega = trace(lo), grid[lo]
        if ok and math.isfinite(best):
            lf = factors[lo]
            wf, wb = omega, 1.0 - omega
            xfe, xbe = xf[e].tolist(), xb[e].tolist()
            t = []
            for i in range(ns):
                sf = sb = 0.0
                for j in range(ns):
                    sf += inf[i * ns + j] * xfe[j]
                    sb += inb[i * ns + j] * xbe[j]
                t.append(wf * sf + wb * sb)
            u = [t[order[i]] for i in range(ns)]
            _cholesky_solve(lf, ns, u)
            xo = [0.0] * ns
            for i in range(ns):
                xo[order[i]] = u[i]
            x_out[e] = xo
            if block == ns:
                inv = _cholesky_inverse(lf, ns)
                po = [0.0] * nn
                for i in range(ns):
                    for j in range(ns):
                        po[order[i] * ns + order[j]] = inv[i * ns + j]
                po2[e] = po
            elif block == 2:  # cholesky_inverse's steps on the factor's last two rows
                la, lc = 1.0 / lf[(ns - 2) * ns + ns - 2], 1.0 / lf[(ns - 1) * ns + ns - 1]
                s = 0.0
                s -= lf[(ns - 1) * ns + ns - 2] * la
                lb = s * lc
                off = 0.0 + lc * lb
                po2[e] = [(0.0 + la * la) + lb * lb, off, off, 0.0 + lc * lc]
        else:
            ok = False
        if not ok:
            x_out[e], omega = math.nan, math.nan
            if block:
                po2[e] = math.nan
        w_out[e] = omega


def residuals(x, sat, pr, mask, clock, origin, rot, n_states, n_slots, omega, c_mps, out):
    """The kernel's ``residuals``: pseudorange less the range from the trajectory ``x`` (E, S) less the
    constellation's clock, into ``out`` (E, N; NaN in empty slots)."""
    n_epochs = out.shape[0]
    c = dict(n_slots=n_slots, omega=omega, c_mps=c_mps, sat=sat.ravel().tolist(), origin=origin.tolist(),
             rot=rot.ravel().tolist())  # fmt: skip
    xs, prs, clocks = x.tolist(), pr.tolist(), clock.tolist()
    out[:] = math.nan
    for k in range(n_epochs):
        used = np.flatnonzero(mask[k]).tolist()
        if not used:
            continue
        rng, _ = _ranges(c, xs[k], k, used)
        for a, j in enumerate(used):
            col = M + max(clocks[k][j], 0)
            out[k, j] = (prs[k][j] - rng[a]) - xs[k][col] if col < n_states else math.nan
