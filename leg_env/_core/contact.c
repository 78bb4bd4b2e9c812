/* Unilateral contact of the point foot with the ground: modes, slip, impact map, Painleve rule.
 *
 * Notation (leg_env.contact's docstring says it for users): J = Jc with rows J_x, J_y,
 * gamma = Jcdot qd, the contact inertia Lambda = J M^-1 J^T (2x2 SPD) and the free foot acceleration
 * a0 = J M^-1 (S^T tau - h) + gamma; a foot force lam gives the foot acceleration a0 + Lambda lam.
 *
 * With the whole-body COM eliminated, the leg angles theta = (th1, th2) obey K theta'' = r + G^T F
 * for a foot force F, K the flight inertia and G the Jacobian of the foot relative to the COM,
 * p_f - p_com = al1 (cos th1, sin th1) + al2 (cos th2, sin th2), al1 = l1 - a/m, al2 = l2 - b/m.
 * Hence Lambda = I/m + G K^-1 G^T and a0 = -g e_y + G K^-1 r + Gdot theta': 2x2 solves by Cramer's rule.
 *
 * Part of the unity build of module.c.
 */
#include <math.h>

#include "robot.h"

/* Consistency margins within this relative tolerance (of m g, or of g for accelerations) are ties
 * broken by the enumeration order, not Painleve cases: round-off at a located transition. */
#define LEG_TIE 1e-9

/* The foot's response to a foot force: Lambda and B = K^-1 G^T (rows th1, th2; columns x, y), and
 * K's entries with 1 / det K, so that free_terms() solves with the same factorisation. */
typedef struct {
    double Lxx, Lxy, Lyy;
    double B1x, B1y, B2x, B2y;
    double K11, K12, K22, inv_det;
} leg_response;

static inline leg_response foot_response_m(const leg_model *M, double s1, double co1, double s2, double co2)
{
    leg_response R;
    R.K11 = M->K11f;
    R.K22 = M->K22f;
    R.K12 = M->kf * (co1 * co2 + s1 * s2);
    R.inv_det = 1.0 / (R.K11 * R.K22 - R.K12 * R.K12);
    const double al1 = M->al1, al2 = M->al2;
    const double g1x = -al1 * s1, g1y = al1 * co1; /* d(p_f - p_com)/d th1 */
    const double g2x = -al2 * s2, g2y = al2 * co2; /* d(p_f - p_com)/d th2 */
    R.B1x = (R.K22 * g1x - R.K12 * g2x) * R.inv_det;
    R.B2x = (R.K11 * g2x - R.K12 * g1x) * R.inv_det;
    R.B1y = (R.K22 * g1y - R.K12 * g2y) * R.inv_det;
    R.B2y = (R.K11 * g2y - R.K12 * g1y) * R.inv_det;
    R.Lxx = M->inv_m + g1x * R.B1x + g2x * R.B2x;
    R.Lxy = g1x * R.B1y + g2x * R.B2y;
    R.Lyy = M->inv_m + g1y * R.B1y + g2y * R.B2y;
    return R;
}

static inline leg_response foot_response(const leg_params *P, double s1, double co1, double s2, double co2)
{
    const leg_model M = model_of(P);
    return foot_response_m(&M, s1, co1, s2, co2);
}

/* Free leg accelerations u = K^-1 r and the free foot acceleration a0. */
typedef struct {
    double u1, u2, a0x, a0y;
} leg_free;

static inline leg_free free_terms_m(const leg_model *M, const leg_response *R, double s1, double co1, double s2,
                                    double co2, double w1, double w2, double tau_hip, double tau_knee, double F)
{
    const double m = M->m, a = M->a, b = M->b, kf = M->kf;
    const double al1 = M->al1, al2 = M->al2;
    const double s12 = s1 * co2 - co1 * s2;
    const double v1 = w1 * w1, v2 = w2 * w2;
    double r1 = (tau_hip - tau_knee) - kf * s12 * v2;
    double r2 = tau_knee + kf * s12 * v1;
    if (F != 0.0) { /* a force on the torso's COM: (a s1, b s2) F / m on the leg, F / m on the COM */
        r1 += F * a * s1 / m;
        r2 += F * b * s2 / m;
    }
    leg_free out;
    out.u1 = (R->K22 * r1 - R->K12 * r2) * R->inv_det;
    out.u2 = (R->K11 * r2 - R->K12 * r1) * R->inv_det;
    out.a0x = -al1 * (s1 * out.u1 + co1 * v1) - al2 * (s2 * out.u2 + co2 * v2) + F / m;
    out.a0y = al1 * (co1 * out.u1 - s1 * v1) + al2 * (co2 * out.u2 - s2 * v2) - M->p.g;
    return out;
}

static inline leg_free free_terms(const leg_params *P, const leg_response *R, double s1, double co1, double s2, double co2,
                                  double w1, double w2, double tau_hip, double tau_knee, double F)
{
    const leg_model M = model_of(P);
    return free_terms_m(&M, R, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
}

/* qdd under the foot force (Fx, Fy) from the free leg accelerations and B. */
static inline leg_accel forced_accel(const leg_model *M, const leg_response *R, const leg_free *u, double s1,
                                     double co1, double s2, double co2, double w1, double w2, double Fx, double Fy,
                                     double tau_hip, double F)
{
    const double m = M->m, a = M->a, b = M->b;
    const double dd1 = u->u1 + R->B1x * Fx + R->B1y * Fy;
    const double dd2 = u->u2 + R->B2x * Fx + R->B2y * Fy;
    leg_accel out;
    /* x_b = x_com - (a cos th1 + b cos th2) / m, and likewise y_b; m p_com'' = F_foot + F e_x - m g e_y */
    out.xdd = (Fx + a * (co1 * w1 * w1 + s1 * dd1) + b * (co2 * w2 * w2 + s2 * dd2) + F) / m;
    out.ydd = (Fy + a * (s1 * w1 * w1 - co1 * dd1) + b * (s2 * w2 * w2 - co2 * dd2)) / m - M->p.g;
    out.thbdd = -tau_hip / M->p.I_b;
    out.q1dd = dd1 - out.thbdd;
    out.q2dd = dd2 - dd1;
    out.lam_x = Fx;
    out.lam_y = Fy;
    return out;
}

/* Slip in direction sigma (+1: +x): only y_f'' = 0 holds, lam = lam_y (-sigma mu, 1) with
 * lam_y = -a0_y / k_sigma, k_sigma = Lambda_yy - sigma mu Lambda_yx. */
static inline leg_accel slip_m(const leg_model *M, double s1, double co1, double s2, double co2, double w1, double w2,
                               double tau_hip, double tau_knee, double F, double mu, double sigma)
{
    const leg_response R = foot_response_m(M, s1, co1, s2, co2);
    const leg_free u = free_terms_m(M, &R, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
    const double k = R.Lyy - sigma * mu * R.Lxy;
    const double lam_y = -u.a0y / k;
    const double lam_x = -sigma * mu * lam_y;
    return forced_accel(M, &R, &u, s1, co1, s2, co2, w1, w2, lam_x, lam_y, tau_hip, F);
}

static inline leg_accel slip_core(const leg_params *P, double s1, double co1, double s2, double co2, double w1,
                                  double w2, double tau_hip, double tau_knee, double F, double mu, double sigma)
{
    const leg_model M = model_of(P);
    return slip_m(&M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F, mu, sigma);
}

/* The foot's velocity v_f = J qd from the base velocity and the link rates. */
static inline void foot_velocity(const leg_params *P, double s1, double co1, double s2, double co2, double vx,
                                 double vy, double w1, double w2, double *vfx, double *vfy)
{
    *vfx = vx - P->l1 * s1 * w1 - P->l2 * s2 * w2;
    *vfy = vy + P->l1 * co1 * w1 + P->l2 * co2 * w2;
}

/* The velocity jump M^-1 J^T P of a foot impulse P, as (d x_b', d y_b', d th_b', d q1', d q2'). */
static inline void impulse_velocity_m(const leg_model *M, const leg_response *R, double s1, double co1, double s2,
                                      double co2, double Px, double Py, double *d)
{
    const double m = M->m, a = M->a, b = M->b;
    const double dw1 = R->B1x * Px + R->B1y * Py;
    const double dw2 = R->B2x * Px + R->B2y * Py;
    d[0] = (Px + a * s1 * dw1 + b * s2 * dw2) / m;
    d[1] = (Py - a * co1 * dw1 - b * co2 * dw2) / m;
    d[2] = 0.0;
    d[3] = dw1;
    d[4] = dw2 - dw1;
}

static inline void impulse_velocity(const leg_params *P, const leg_response *R, double s1, double co1, double s2,
                                    double co2, double Px, double Py, double *d)
{
    const leg_model M = model_of(P);
    impulse_velocity_m(&M, R, s1, co1, s2, co2, Px, Py, d);
}

/* Plastic (e = 0) foot impulse for the foot velocity v_f-; returns a leg_impact status.
 * mu = inf: the bilateral sticking impulse -Lambda^-1 v_f- for any velocity. Finite mu: no impulse
 * unless the foot approaches; the sticking impulse inside the cone; otherwise Routh's incremental
 * sliding impact (a sliding phase along (-sigma mu, 1), then a sticking phase or reversed sliding). */
static leg_impact impact_core(double vfx, double vfy, double mu, double Lxx, double Lxy, double Lyy, double *Px_out,
                              double *Py_out)
{
    const double det = Lxx * Lyy - Lxy * Lxy;
    const double Px = -(Lyy * vfx - Lxy * vfy) / det;
    const double Py = -(Lxx * vfy - Lxy * vfx) / det;
    *Px_out = Px;
    *Py_out = Py;
    if (isinf(mu))
        return LEG_IMPACT_STICK;
    if (!(vfy < 0.0)) {
        *Px_out = 0.0;
        *Py_out = 0.0;
        return LEG_IMPACT_NONE;
    }
    if (Py >= 0.0 && fabs(Px) <= mu * Py)
        return LEG_IMPACT_STICK;
    const double sigma = vfx > 0.0 ? 1.0 : (vfx < 0.0 ? -1.0 : (Px < 0.0 ? 1.0 : -1.0));
    const double k = Lyy - sigma * mu * Lxy; /* d v_fy / d P_y while sliding in direction sigma */
    if (k <= 0.0)
        return LEG_IMPACT_PAINLEVE;
    const double r = Lxy - sigma * mu * Lxx; /* d v_fx / d P_y while sliding */
    const double p_end = -vfy / k;
    if (sigma * (vfx + r * p_end) >= 0.0) { /* slides the whole impact */
        *Px_out = -sigma * mu * p_end;
        *Py_out = p_end;
        return LEG_IMPACT_SLIDE;
    }
    const double p1 = -vfx / r; /* sliding stops here, with the foot still approaching */
    const double vfy1 = vfy + k * p1;
    if (fabs(Lxy) <= mu * Lxx) { /* then sticks: dPx = -(Lxy / Lxx) dPy keeps v_fx = 0 */
        const double p2 = -vfy1 * Lxx / det;
        *Px_out = -sigma * mu * p1 - (Lxy / Lxx) * p2;
        *Py_out = p1 + p2;
        return LEG_IMPACT_SLIDE;
    }
    const double s2 = Lxy > 0.0 ? 1.0 : -1.0; /* else slides back, the way a normal impulse pushes the foot */
    const double k2 = Lyy - s2 * mu * Lxy;
    if (k2 <= 0.0)
        return LEG_IMPACT_PAINLEVE;
    const double p2 = -vfy1 / k2;
    *Px_out = -sigma * mu * p1 - s2 * mu * p2;
    *Py_out = p1 + p2;
    return LEG_IMPACT_SLIDE;
}

/* The consistent mode of a foot at rest on the ground, by enumeration (stick, slip, flight); `exclude`
 * is a mode that a located transition has just made inconsistent, or -1. With no consistent
 * candidate (past the Painleve bound) the foot sticks and *painleve is set. */
static int mode_at_rest_m(const leg_model *M, double s1, double co1, double s2, double co2, double w1, double w2,
                          double tau_hip, double tau_knee, double F, double mu, int exclude, int *painleve)
{
    const double m = M->m;
    const double f_scale = m * leg_fmax(M->p.g, 1.0); /* forces: the weight (or mass x 1 m/s^2 without gravity) */
    const double a_scale = leg_fmax(M->p.g, 1.0);
    const double tie = -LEG_TIE;
    *painleve = 0;
    const leg_accel st = stance_m(M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
    const double lam_x = st.lam_x, lam_y = st.lam_y;
    if (exclude != LEG_STICK && lam_y / f_scale >= tie && (mu * lam_y - fabs(lam_x)) / f_scale >= tie)
        return LEG_STICK;
    const leg_response R = foot_response_m(M, s1, co1, s2, co2);
    const leg_free u = free_terms_m(M, &R, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
    const double first = lam_x > 0.0 ? -1.0 : 1.0; /* the slip opposite to the friction the stick needed */
    for (int n = 0; n < 2; n++) {
        const double sigma = n == 0 ? first : -first;
        const int mode = sigma > 0.0 ? LEG_SLIP_FORWARD : LEG_SLIP_BACKWARD;
        const double k = R.Lyy - sigma * mu * R.Lxy;
        if (mode == exclude || k <= 0.0)
            continue;
        const double ly = -u.a0y / k;
        const double xdd = u.a0x + (R.Lxy - sigma * mu * R.Lxx) * ly;
        if (ly / f_scale >= tie && sigma * xdd / a_scale >= tie)
            return mode;
    }
    if (exclude != LEG_FLIGHT && u.a0y / a_scale >= tie)
        return LEG_FLIGHT;
    *painleve = 1;
    return LEG_STICK;
}

/* The mode of a foot sliding in direction sigma: slip if its normal force is compressive, else
 * flight. Past the Painleve bound (k_sigma <= 0, *painleve set): flight if a0_y >= 0, else -1 (no
 * consistent force: the caller stops the foot by a tangential impact). */
static int mode_sliding_m(const leg_model *M, double s1, double co1, double s2, double co2, double w1, double w2,
                          double tau_hip, double tau_knee, double F, double mu, double sigma, int *painleve)
{
    const leg_response R = foot_response_m(M, s1, co1, s2, co2);
    const leg_free u = free_terms_m(M, &R, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
    const double k = R.Lyy - sigma * mu * R.Lxy;
    *painleve = 0;
    if (k <= 0.0) {
        *painleve = 1;
        return u.a0y >= 0.0 ? LEG_FLIGHT : -1;
    }
    if (u.a0y <= 0.0) /* lam_y = -a0y / k >= 0 */
        return sigma > 0.0 ? LEG_SLIP_FORWARD : LEG_SLIP_BACKWARD;
    return LEG_FLIGHT;
}

/* contact_mode() of one robot: the mode at rest, or the sliding mode (flight where none is consistent). */
static int contact_mode_one(const leg_params *P, const double *q, const double *qd, double tau_hip, double tau_knee,
                            double mu)
{
    double s1, co1, s2, co2, vfx, vfy;
    int painleve;
    const leg_model M = model_of(P);
    leg_trig(q, &s1, &co1, &s2, &co2);
    const double w1 = qd[2] + qd[3], w2 = w1 + qd[4];
    foot_velocity(P, s1, co1, s2, co2, qd[0], qd[1], w1, w2, &vfx, &vfy);
    if (fabs(vfx) <= LEG_REST_SPEED)
        return mode_at_rest_m(&M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, 0.0, mu, -1, &painleve);
    const int mode = mode_sliding_m(&M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, 0.0, mu, vfx > 0.0 ? 1.0 : -1.0,
                                    &painleve);
    return mode < 0 ? LEG_FLIGHT : mode;
}
