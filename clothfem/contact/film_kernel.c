/* The FILM contact correction of clothfem.contact.explicit.film_step, one loop over nodes.
 *
 * The same algorithm, step for step and in the same floating-point order where NumPy's is
 * fixed, as the NumPy reference `_film_numpy` in explicit.py (its docstrings state the
 * physics: Eqs. 22-25 of Man & Swan 2007, Eberly's exact closest point, the union rule, the
 * overlap re-projection passes, Coulomb's law on impulses). Every node is corrected
 * independently of the others once the two global round-off scales are known, so the loop
 * needs no temporary arrays. Compiled by clothfem.contact.compiled (no -ffast-math, no FMA
 * contraction: IEEE arithmetic as NumPy's).
 *
 * Ellipsoid k: centre c[3k..], axes as the columns of the row-major 3x3 Q[9k..]
 * (Q[9k + 3i + j] = component i of axis j), radii r[3k..]; velocities vc[3k..], om[3k..].
 */
#include <math.h>
#include <stdint.h>

#define TINY 1e-150

static void local_coords(const double *x, const double *c, const double *Q, double *y)
{
    double d0 = x[0] - c[0], d1 = x[1] - c[1], d2 = x[2] - c[2];
    for (int j = 0; j < 3; ++j)
        y[j] = d0 * Q[j] + d1 * Q[3 + j] + d2 * Q[6 + j];
}

static double rmin3(const double *r) { return fmin(fmin(r[0], r[1]), r[2]); }

/* (sqrt(f + 1) - 1) r_min with f the Eq. 26 value: gap lower bound outside, < 0 inside */
static double lower_bound(const double *x, const double *c, const double *Q, const double *r)
{
    double y[3];
    local_coords(x, c, Q, y);
    double a = y[0] / r[0], b = y[1] / r[1], e = y[2] / r[2];
    double f = a * a + b * b + e * e - 1.0;
    return (sqrt(f + 1.0) - 1.0) * rmin3(r);
}

/* closest point of z >= 0 on sum (p_i / rs_i)^2 = 1, largest radius 1 (Eberly) */
static void octant(const double *z, const double *rs, double tol, long max_iter, double *p)
{
    double rmin = rmin3(rs), delta[3], a[3];
    int on[3];
    double zmin_sum = 0.0, F0 = 0.0;
    for (int i = 0; i < 3; ++i) {
        delta[i] = (rs[i] - rmin) * (rs[i] + rmin);
        on[i] = delta[i] == 0.0;
        double rz = rs[i] * z[i];
        a[i] = rz * rz;
        zmin_sum += on[i] ? z[i] : 0.0;
        F0 += on[i] ? 0.0 : a[i] / (delta[i] * delta[i]);
    }
    F0 -= 1.0;
    if (zmin_sum == 0.0 && F0 <= 0.0) {
        int kmin = on[0] ? 0 : (on[1] ? 1 : 2);
        for (int i = 0; i < 3; ++i)
            p[i] = on[i] ? 0.0 : rs[i] * rs[i] * z[i] / delta[i];
        p[kmin] = rmin * sqrt(fmax(-F0, 0.0));
    } else {
        double norm_rz = sqrt(a[0] + a[1] + a[2]);
        double lo = 0.0, dmax = fmax(fmax(delta[0], delta[1]), delta[2]);
        for (int i = 0; i < 3; ++i)
            lo = fmax(lo, sqrt(a[i]) - delta[i]);
        lo = fmax(lo, norm_rz - dmax);
        double hi = norm_rz;
        double s = lo > 0.0 ? lo : hi;
        for (long it = 0; it < max_iter; ++it) {
            double u = 0.0, up = 0.0;
            for (int i = 0; i < 3; ++i) {
                double d = s + delta[i];
                double q = a[i] / (d * d);
                u += q;
                up += q / d;
            }
            if (u > 1.0) lo = s;
            if (u < 1.0) hi = s;
            double s_nt = s - u * (1.0 - sqrt(u)) / up;
            int ok = (s_nt >= lo) && (s_nt <= hi);
            double s_new = ok ? s_nt : 0.5 * (lo + hi);
            int done = (ok && fabs(s_new - s) <= tol * s_new) || (hi - lo <= tol * hi);
            s = s_new;
            if (done) break;
        }
        for (int i = 0; i < 3; ++i)
            p[i] = rs[i] * rs[i] * z[i] / (s + delta[i]);
    }
    double w0 = p[0] / rs[0], w1 = p[1] / rs[1], w2 = p[2] / rs[2];
    double nrm = sqrt(w0 * w0 + w1 * w1 + w2 * w2);
    for (int i = 0; i < 3; ++i)
        p[i] /= nrm;
}

/* exact closest point on one ellipsoid: point, outward normal, signed gap */
static double closest(const double *x, const double *c, const double *Q, const double *r,
                      double tol, long max_iter, double *pt, double *nrm)
{
    double y[3], z[3], rs[3], sg[3], p[3], pl[3], nl[3];
    local_coords(x, c, Q, y);
    double scale = fmax(fmax(r[0], r[1]), r[2]);
    for (int i = 0; i < 3; ++i) {
        double ys = y[i] / scale;
        z[i] = fabs(ys) < TINY ? 0.0 : fabs(ys);
        rs[i] = r[i] / scale;
        sg[i] = ys < 0.0 ? -1.0 : 1.0;
    }
    octant(z, rs, tol, max_iter, p);
    for (int i = 0; i < 3; ++i) {
        pl[i] = sg[i] * p[i] * scale;
        nl[i] = pl[i] / (r[i] * r[i]);
    }
    double nn = sqrt(nl[0] * nl[0] + nl[1] * nl[1] + nl[2] * nl[2]);
    double gap = 0.0;
    for (int i = 0; i < 3; ++i) {
        nl[i] /= nn;
        gap += (y[i] - pl[i]) * nl[i];
    }
    for (int i = 0; i < 3; ++i) {
        pt[i] = c[i] + (pl[0] * Q[3 * i] + pl[1] * Q[3 * i + 1] + pl[2] * Q[3 * i + 2]);
        nrm[i] = nl[0] * Q[3 * i] + nl[1] * Q[3 * i + 1] + nl[2] * Q[3 * i + 2];
    }
    return gap;
}

typedef struct {
    long K;
    const double *c, *Q, *r;
    double tol;
    long max_iter;
} Bodies;

/* union rule: the ellipsoid of smallest gap (ties: lower index), projecting first on the
 * one of smallest lower bound and on another only where its bound does not clear that gap */
static double closest_union(const double *x, const Bodies *B, double *pt, double *nrm, long *body)
{
    if (B->K == 1) {
        *body = 0;
        return closest(x, B->c, B->Q, B->r, B->tol, B->max_iter, pt, nrm);
    }
    long first = 0;
    double lb_first = INFINITY;
    for (long k = 0; k < B->K; ++k) {
        double lb = lower_bound(x, B->c + 3 * k, B->Q + 9 * k, B->r + 3 * k);
        if (lb < lb_first) lb_first = lb, first = k;
    }
    double gap0 = closest(x, B->c + 3 * first, B->Q + 9 * first, B->r + 3 * first, B->tol,
                          B->max_iter, pt, nrm);
    double best = gap0;
    *body = first;
    for (long k = 0; k < B->K; ++k) {
        if (k == first) continue;
        double lb = lower_bound(x, B->c + 3 * k, B->Q + 9 * k, B->r + 3 * k);
        if (!(lb < 0.0 || lb <= gap0)) continue;
        double p[3], n[3];
        double g = closest(x, B->c + 3 * k, B->Q + 9 * k, B->r + 3 * k, B->tol, B->max_iter, p, n);
        if (g < best || (g == best && k < *body)) {
            best = g, *body = k;
            for (int i = 0; i < 3; ++i) pt[i] = p[i], nrm[i] = n[i];
        }
    }
    return best;
}

/* some ellipsoid other than `own` has a gap lower bound below `cut` */
static int near_others(const double *x, long own, const Bodies *B, double cut)
{
    for (long k = 0; k < B->K; ++k)
        if (k != own && lower_bound(x, B->c + 3 * k, B->Q + 9 * k, B->r + 3 * k) < cut) return 1;
    return 0;
}

int film_correct(long n, const double *xs, const double *vs, const double *m, double dt, long K,
                 const double *c, const double *Q, const double *r, const double *vc,
                 const double *om, int has_mu, double mu, double offset, long max_passes,
                 double tol, long max_iter, double gap_tol, const uint8_t *fixed,
                 double *x, double *v,
                 uint8_t *active, double *lam_n, double *force, double *friction,
                 double *normal, int64_t *body, double *gap, uint8_t *stick,
                 double *dissipation, uint8_t *unresolved)
{
    Bodies B = {K, c, Q, r, tol, max_iter};
    double dt2 = dt * dt;
    double scale = 1.0; /* over the nodes that may be corrected */
    for (long i = 0; i < 3 * n; ++i)
        if (!fixed || !fixed[i / 3]) scale = fmax(scale, fabs(xs[i]));
    double near_cut = offset + gap_tol * scale;

    /* broad phase, projection, activity; the contact point is kept in x for now */
    double amax = 1.0;
    long n_active = 0;
    for (long i = 0; i < n; ++i) {
        const double *xi = xs + 3 * i;
        int skip = fixed && fixed[i]; /* a fixed node: as it came, gap not evaluated */
        double g = INFINITY;
        for (long k = 0; k < K && !skip; ++k)
            g = fmin(g, lower_bound(xi, c + 3 * k, Q + 9 * k, r + 3 * k));
        double p[3], nr[3];
        long bk = -1;
        if (!skip && g < near_cut) g = closest_union(xi, &B, p, nr, &bk);
        gap[i] = g;
        active[i] = g < offset;
        stick[i] = unresolved[i] = 0;
        lam_n[i] = dissipation[i] = 0.0;
        body[i] = -1;
        for (int j = 0; j < 3; ++j) {
            x[3 * i + j] = xs[3 * i + j];
            v[3 * i + j] = vs[3 * i + j];
            normal[3 * i + j] = friction[3 * i + j] = 0.0;
        }
        if (active[i]) {
            ++n_active;
            body[i] = bk;
            for (int j = 0; j < 3; ++j) {
                x[3 * i + j] = p[j];
                normal[3 * i + j] = nr[j];
                amax = fmax(amax, fabs(p[j] + offset * nr[j]));
            }
        }
    }
    double tol_gap = gap_tol * amax;

    for (long i = 0; i < n && n_active; ++i) {
        if (!active[i]) continue;
        double p[3], nr[3], xa[3];
        long bk = body[i];
        for (int j = 0; j < 3; ++j) {
            p[j] = x[3 * i + j];
            nr[j] = normal[3 * i + j];
            xa[j] = p[j] + offset * nr[j];
        }
        /* overlap regions: re-project while the target is within offset of another one */
        if (K > 1) {
            for (long pass = 0; pass < max_passes - 1; ++pass) {
                if (!near_others(xa, bk, &B, offset)) break;
                double cp[3], cn[3];
                long cb;
                double g = closest_union(xa, &B, cp, cn, &cb);
                if (!(g < offset - tol_gap)) break;
                bk = cb;
                for (int j = 0; j < 3; ++j) {
                    p[j] = cp[j], nr[j] = cn[j];
                    xa[j] = p[j] + offset * nr[j];
                }
            }
        }
        const double *xsi = xs + 3 * i, *vsi = vs + 3 * i;
        double ma = m[i];
        double dn = (xa[0] - xsi[0]) * nr[0] + (xa[1] - xsi[1]) * nr[1] + (xa[2] - xsi[2]) * nr[2];
        lam_n[i] = ma * dn / dt2;

        /* post-impact velocity: non-resilient normal, friction on the tangential part */
        const double *ck = c + 3 * bk, *w = om + 3 * bk, *vck = vc + 3 * bk;
        double d[3] = {p[0] - ck[0], p[1] - ck[1], p[2] - ck[2]};
        double vb[3] = {vck[0] + (w[1] * d[2] - w[2] * d[1]), vck[1] + (w[2] * d[0] - w[0] * d[2]),
                        vck[2] + (w[0] * d[1] - w[1] * d[0])};
        double vrel[3], vt[3], dvt[3];
        for (int j = 0; j < 3; ++j) vrel[j] = vsi[j] - vb[j];
        double vrel_n = vrel[0] * nr[0] + vrel[1] * nr[1] + vrel[2] * nr[2];
        for (int j = 0; j < 3; ++j) vt[j] = vrel[j] - vrel_n * nr[j];
        double dv_n = -vrel_n;
        if (!has_mu) {
            for (int j = 0; j < 3; ++j) dvt[j] = -vt[j];
            stick[i] = 1;
        } else if (mu == 0.0) { /* frictionless: tangential velocity unchanged */
            for (int j = 0; j < 3; ++j) dvt[j] = 0.0;
        } else {
            double lam = ma * fabs(dv_n) / dt, k_t = ma / dt2, cap = mu * lam, tr[3], f[3], sl[3];
            for (int j = 0; j < 3; ++j) tr[j] = -ma * vt[j] / dt;
            double mag = sqrt(tr[0] * tr[0] + tr[1] * tr[1] + tr[2] * tr[2]);
            int st = mag <= cap;
            double sc = st ? 1.0 : cap / mag;
            for (int j = 0; j < 3; ++j) {
                f[j] = tr[j] * sc;
                sl[j] = -(tr[j] - f[j]) / k_t;
                dvt[j] = f[j] * dt / ma;
            }
            stick[i] = st;
            dissipation[i] = cap * sqrt(sl[0] * sl[0] + sl[1] * sl[1] + sl[2] * sl[2]);
        }
        for (int j = 0; j < 3; ++j) v[3 * i + j] = vsi[j] + dv_n * nr[j] + dvt[j];
        /* tangential friction displacement, then back onto the contact ellipsoid */
        if (dvt[0] != 0.0 || dvt[1] != 0.0 || dvt[2] != 0.0) {
            double xm[3], pt[3], nm[3];
            for (int j = 0; j < 3; ++j) xm[j] = xa[j] + dt * dvt[j];
            closest(xm, c + 3 * bk, Q + 9 * bk, r + 3 * bk, tol, max_iter, pt, nm);
            for (int j = 0; j < 3; ++j) xa[j] = pt[j] + offset * nm[j];
        }
        for (int j = 0; j < 3; ++j) {
            x[3 * i + j] = xa[j];
            friction[3 * i + j] = ma * dvt[j] / dt;
            normal[3 * i + j] = nr[j];
        }
        body[i] = bk;
        /* final gap: offset from the own body, less only where another may come closer */
        double fin = offset;
        if (near_others(xa, bk, &B, offset)) {
            double cp[3], cn[3];
            long cb;
            fin = closest_union(xa, &B, cp, cn, &cb);
        }
        gap[i] = fin;
        unresolved[i] = fin < offset - tol_gap;
    }
    for (long i = 0; i < 3 * n; ++i) force[i] = m[i / 3] * (x[i] - xs[i]) / dt2;
    return 0;
}
