/* Analytic floating-base dynamics of the planar leg (the lesson's sections 1-5).
 *
 * In absolute coordinates z = (x_b, y_b, th_b, th1, th2) = T q the mass matrix is sparse,
 * M = T^T A T and h = T^T h_z. The hip sits at the torso's COM, so the torso row decouples:
 * th_b'' = -tau_hip / I_b in flight and in stance. What is left of each mode is a 2x2 symmetric
 * positive definite system in the leg angles, solved by Cramer's rule; nothing is inverted.
 * A horizontal force F on the torso's COM (a push) adds Q = (F, 0, 0, 0, 0) to the right-hand side.
 *
 * Part of the unity build of module.c (one translation unit, so that the compiler inlines across
 * files): include only from there.
 */
#include <math.h>

#include "robot.h"

/* The sines and cosines of th1 = th_b + q1 and th2 = th1 + q2 at q. */
static inline void leg_trig(const double *q, double *s1, double *c1, double *s2, double *c2)
{
    double th1 = q[2] + q[3];
    double th2 = th1 + q[4];
    *s1 = sin(th1);
    *c1 = cos(th1);
    *s2 = sin(th2);
    *c2 = cos(th2);
}

/* The leg's motion about the whole-body COM: total mass m, first moments a = m1 c1 + m2 l1 (leg about
 * the hip) and b = m2 c2 (shank about the knee), and the flight inertia of the absolute leg angles
 * K = [[K11, kf cos(th1 - th2)], [kf cos(th1 - th2), K22]]. */
typedef struct {
    double m, a, b, kf, K11, K22;
} leg_flight_inertia;

static inline leg_flight_inertia flight_inertia(const leg_params *P)
{
    const double m_b = P->m_b, m1 = P->m1, m2 = P->m2, I1 = P->I1, I2 = P->I2;
    const double l1 = P->l1, c1 = P->c1, c2 = P->c2;
    leg_flight_inertia f;
    f.m = m_b + m1 + m2;
    f.a = m1 * c1 + m2 * l1;
    f.b = m2 * c2;
    f.kf = m2 * l1 * c2 - f.a * f.b / f.m;
    f.K11 = I1 + m1 * c1 * c1 + m2 * l1 * l1 - f.a * f.a / f.m;
    f.K22 = I2 + m2 * c2 * c2 - f.b * f.b / f.m;
    return f;
}

/* A robot's parameters with the constants of its dynamics computed once (per control step rather than
 * per RK4 stage): the same expressions as flight_inertia() and stance_m(), so the same bits. */
typedef struct {
    leg_params p;               /* first: a leg_model is also its leg_params */
    double m, inv_m, a, b;      /* total mass, 1 / m, first moments of the leg about the hip and the shank about the knee */
    double kf, K11f, K22f;      /* the flight inertia of the leg angles (flight_inertia) */
    double e1, e2, kap, K11s, K22s; /* the leg seen from the pinned foot (stance_m) */
    double al1, al2;            /* the foot relative to the COM: l1 - a / m, l2 - b / m */
} leg_model;

/* Fill M from the parameters P, in place: a control step builds its model where it keeps it (a returned
 * struct copied into place costs the hybrid step a stalled store-to-load forwarding, about 5% of it). */
static inline void model_init(leg_model *M, const leg_params *P)
{
    const double m_b = P->m_b, m1 = P->m1, m2 = P->m2, I1 = P->I1, I2 = P->I2;
    const double l1 = P->l1, l2 = P->l2, c1 = P->c1, c2 = P->c2;
    const leg_flight_inertia f = flight_inertia(P);
    M->p = *P;
    M->m = f.m;
    M->inv_m = 1.0 / f.m;
    M->a = f.a;
    M->b = f.b;
    M->kf = f.kf;
    M->K11f = f.K11;
    M->K22f = f.K22;
    M->e1 = m_b * l1 + m1 * (l1 - c1);
    M->e2 = (m_b + m1) * l2 + m2 * (l2 - c2);
    M->kap = l2 * M->e1;
    M->K11s = I1 + m1 * ((l1 - c1) * (l1 - c1)) + m_b * l1 * l1;
    M->K22s = I2 + m2 * ((l2 - c2) * (l2 - c2)) + (m_b + m1) * l2 * l2;
    M->al1 = l1 - f.a / f.m;
    M->al2 = l2 - f.b / f.m;
}

/* The model of P, returned (for the single-shot entry points). */
static inline leg_model model_of(const leg_params *P)
{
    leg_model M;
    model_init(&M, P);
    return M;
}

/* Stance (foot pinned): the KKT solve from the link angles' sines/cosines and rates w1 = th1',
 * w2 = th2'. Seen from the foot the leg is an inverted double pendulum carrying the torso as a point
 * mass at the hip; eliminating (x_b, y_b) leaves, in the absolute leg angles,
 *
 *   [K11      kap c12] [th1'']   [tau_hip - tau_knee + g e1 cos th1 - kap s12 th2'^2 + F l1 s1]
 *   [kap c12  K22    ] [th2''] = [tau_knee           + g e2 cos th2 + kap s12 th1'^2 + F l2 s2]
 *
 *   K11 = I1 + m1 (l1 - c1)^2 + m_b l1^2          e1 = m_b l1 + m1 (l1 - c1)
 *   K22 = I2 + m2 (l2 - c2)^2 + (m_b + m1) l2^2   e2 = (m_b + m1) l2 + m2 (l2 - c2)
 *   kap = l2 e1,  c12 = cos(th1 - th2),  s12 = sin(th1 - th2)
 *
 * The base follows from the contact and lam = m a_com + m g e_y - F e_x. */
LEG_INLINE leg_accel stance_m(const leg_model *M, double s1, double co1, double s2, double co2, double w1, double w2,
                                 double tau_hip, double tau_knee, double F)
{
    const double I_b = M->p.I_b, l1 = M->p.l1, l2 = M->p.l2, g = M->p.g;
    const double m = M->m, e1 = M->e1, e2 = M->e2, kap = M->kap, K11 = M->K11s, K22 = M->K22s;
    const double c12 = co1 * co2 + s1 * s2;
    const double s12 = s1 * co2 - co1 * s2;
    const double K12 = kap * c12;
    const double v1 = w1 * w1, v2 = w2 * w2;
    const double r1 = (tau_hip - tau_knee) + g * e1 * co1 - kap * s12 * v2 + F * l1 * s1;
    const double r2 = tau_knee + g * e2 * co2 + kap * s12 * v1 + F * l2 * s2;
    const double inv_det = 1.0 / (K11 * K22 - K12 * K12);
    const double dd1 = (K22 * r1 - K12 * r2) * inv_det;
    const double dd2 = (K11 * r2 - K12 * r1) * inv_det;
    /* accelerations of the knee relative to the foot (ux, uy) and of the hip relative to the knee (vx, vy), per length */
    const double ux = co2 * v2 + s2 * dd2, uy = s2 * v2 - co2 * dd2;
    const double vx = co1 * v1 + s1 * dd1, vy = s1 * v1 - co1 * dd1;
    leg_accel out;
    out.xdd = l1 * vx + l2 * ux;
    out.ydd = l1 * vy + l2 * uy;
    out.thbdd = -tau_hip / I_b;
    out.q1dd = dd1 - out.thbdd;
    out.q2dd = dd2 - dd1;
    out.lam_x = e1 * vx + e2 * ux - F;
    out.lam_y = e1 * vy + e2 * uy + m * g;
    return out;
}

static inline leg_accel stance_core(const leg_params *P, double s1, double co1, double s2, double co2, double w1,
                                    double w2, double tau_hip, double tau_knee, double F)
{
    const leg_model M = model_of(P);
    return stance_m(&M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
}

/* Flight (no contact): the COM falls freely, m p_com'' = (F, -m g), and the leg angles obey
 *
 *   [K11     kf c12] [th1'']   [tau_hip - tau_knee - kf s12 th2'^2 + F a s1 / m]
 *   [kf c12  K22   ] [th2''] = [tau_knee           + kf s12 th1'^2 + F b s2 / m]
 *
 * with the flight inertia of flight_inertia(). */
LEG_INLINE leg_accel flight_m(const leg_model *M, double s1, double co1, double s2, double co2, double w1, double w2,
                                 double tau_hip, double tau_knee, double F)
{
    const double I_b = M->p.I_b, g = M->p.g;
    const double m = M->m, a = M->a, b = M->b, kf = M->kf, K11 = M->K11f, K22 = M->K22f;
    const double c12 = co1 * co2 + s1 * s2;
    const double s12 = s1 * co2 - co1 * s2;
    const double K12 = kf * c12;
    const double v1 = w1 * w1, v2 = w2 * w2;
    double r1 = (tau_hip - tau_knee) - kf * s12 * v2;
    double r2 = tau_knee + kf * s12 * v1;
    if (F != 0.0) { /* a force on the torso's COM; without one these terms are 0 and their two divisions are skipped */
        r1 += F * a * s1 / m;
        r2 += F * b * s2 / m;
    }
    const double inv_det = 1.0 / (K11 * K22 - K12 * K12);
    const double dd1 = (K22 * r1 - K12 * r2) * inv_det;
    const double dd2 = (K11 * r2 - K12 * r1) * inv_det;
    leg_accel out;
    out.thbdd = -tau_hip / I_b;
    /* x_b = x_com - (a cos th1 + b cos th2) / m, and likewise y_b */
    out.xdd = (a * (co1 * v1 + s1 * dd1) + b * (co2 * v2 + s2 * dd2) + F) / m;
    out.ydd = (a * (s1 * v1 - co1 * dd1) + b * (s2 * v2 - co2 * dd2)) / m - g;
    out.q1dd = dd1 - out.thbdd;
    out.q2dd = dd2 - dd1;
    out.lam_x = 0.0;
    out.lam_y = 0.0;
    return out;
}

static inline leg_accel flight_core(const leg_params *P, double s1, double co1, double s2, double co2, double w1,
                                    double w2, double tau_hip, double tau_knee, double F)
{
    const leg_model M = model_of(P);
    return flight_m(&M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
}

/* Mechanical energy T + V [J] from the link trigonometry, base height, the whole-body COM's velocity
 * (vcx, vcy) and the rates (Koenig: T = m |v_com|^2 / 2 + I_b th_b'^2 / 2 + theta'^T K theta' / 2,
 * V = m g y_com), with the flight inertia f of the robot's parameters. */
static inline double energy_flight(const leg_flight_inertia *f, double I_b, double g, double s1, double co1, double s2,
                                   double co2, double y_b, double vcx, double vcy, double w_b, double w1, double w2)
{
    const double m = f->m, a = f->a, b = f->b;
    const double K12 = f->kf * (co1 * co2 + s1 * s2);
    const double T = 0.5 * (m * (vcx * vcx + vcy * vcy) + I_b * w_b * w_b + f->K11 * w1 * w1 + 2.0 * K12 * w1 * w2
                            + f->K22 * w2 * w2);
    return T + g * (m * y_b + a * s1 + b * s2);
}

/* energy_flight from the parameters and the base velocity (vx, vy) and rates. */
static inline double energy_core(const leg_params *P, double s1, double co1, double s2, double co2, double y_b,
                                 double vx, double vy, double w_b, double w1, double w2)
{
    const leg_flight_inertia f = flight_inertia(P);
    const double vcx = vx - (f.a * s1 * w1 + f.b * s2 * w2) / f.m;
    const double vcy = vy + (f.a * co1 * w1 + f.b * co2 * w2) / f.m;
    return energy_flight(&f, P->I_b, P->g, s1, co1, s2, co2, y_b, vcx, vcy, w_b, w1, w2);
}

/* M(q) (section 2), written into M (5x5, row-major). */
static void mass_matrix_one(const leg_params *P, const double *q, double *M)
{
    const double m_b = P->m_b, m1 = P->m1, m2 = P->m2, I_b = P->I_b, I1 = P->I1, I2 = P->I2;
    const double l1 = P->l1, c1 = P->c1, c2 = P->c2;
    const double th1 = q[2] + q[3], th2 = th1 + q[4];
    const double m = m_b + m1 + m2, a = m1 * c1 + m2 * l1, b = m2 * c2;
    const double s1 = sin(th1), co1 = cos(th1), s2 = sin(th2), co2 = cos(th2);
    const double D11 = I1 + m1 * c1 * c1 + m2 * l1 * l1;
    const double D22 = I2 + m2 * c2 * c2;
    const double D12 = m2 * l1 * c2 * cos(th1 - th2);
    /* M = T^T A T written out: columns 2, 3 see th1 and th2; column 4 sees th2 only */
    const double Mx1 = -a * s1 - b * s2, My1 = a * co1 + b * co2;
    const double Mx2 = -b * s2, My2 = b * co2;
#define AT(i, j) M[(i) * LEG_NQ + (j)]
    AT(0, 0) = m;
    AT(0, 1) = 0.0;
    AT(1, 1) = m;
    AT(0, 2) = Mx1;
    AT(0, 3) = Mx1;
    AT(0, 4) = Mx2;
    AT(1, 2) = My1;
    AT(1, 3) = My1;
    AT(1, 4) = My2;
    AT(2, 2) = I_b + D11 + D22 + 2.0 * D12;
    AT(2, 3) = D11 + D22 + 2.0 * D12;
    AT(3, 3) = D11 + D22 + 2.0 * D12;
    AT(2, 4) = D22 + D12;
    AT(3, 4) = D22 + D12;
    AT(4, 4) = D22;
    for (int i = 0; i < LEG_NQ; i++)
        for (int j = 0; j < i; j++)
            AT(i, j) = AT(j, i);
#undef AT
}

/* h from the link angles' sines/cosines, s12 = sin(th1 - th2) and the rates w1 = th1', w2 = th2'. */
static void bias_trig(const leg_params *P, double s1, double co1, double s2, double co2, double s12, double w1, double w2,
                      double *h)
{
    const double m2 = P->m2, l1 = P->l1, c2 = P->c2, g = P->g;
    const double m = P->m_b + P->m1 + m2, a = P->m1 * P->c1 + m2 * l1, b = m2 * c2;
    const double k = m2 * l1 * c2;
    const double hx = -a * co1 * w1 * w1 - b * co2 * w2 * w2;
    const double hy = -a * s1 * w1 * w1 - b * s2 * w2 * w2 + m * g;
    const double h1 = k * s12 * w2 * w2 + a * g * co1;
    const double h2 = -k * s12 * w1 * w1 + b * g * co2;
    h[0] = hx;
    h[1] = hy;
    h[2] = h1 + h2;
    h[3] = h1 + h2;
    h[4] = h2;
}

/* h(q, qd): Coriolis, centrifugal and gravity generalised forces; gravity alone if gravity_only. */
static void bias_one(const leg_params *P, const double *q, const double *qd, int gravity_only, double *h)
{
    const double th1 = q[2] + q[3], th2 = th1 + q[4];
    double w1 = qd[2] + qd[3], w2 = w1 + qd[4];
    const double s1 = sin(th1), co1 = cos(th1), s2 = sin(th2), co2 = cos(th2);
    if (gravity_only) {
        w1 = 0.0;
        w2 = 0.0;
    }
    bias_trig(P, s1, co1, s2, co2, sin(th1 - th2), w1, w2, h);
}

/* The foot position from the base position (x, y) and the link angles' sines/cosines. */
static inline void foot_trig(const leg_params *P, double x, double y, double s1, double co1, double s2, double co2, double *out)
{
    out[0] = x + P->l1 * co1 + P->l2 * co2;
    out[1] = y + P->l1 * s1 + P->l2 * s2;
}

/* The foot position p_f(q) (section 3). */
static void foot_one(const leg_params *P, const double *q, double *out)
{
    const double th1 = q[2] + q[3], th2 = th1 + q[4];
    foot_trig(P, q[0], q[1], sin(th1), cos(th1), sin(th2), cos(th2), out);
}

/* The contact Jacobian from the link angles' sines/cosines. */
static inline void jacobian_trig(const leg_params *P, double s1, double co1, double s2, double co2, double *Jc)
{
    const double J1x = -P->l1 * s1, J1y = P->l1 * co1;
    const double J2x = -P->l2 * s2, J2y = P->l2 * co2;
    Jc[0] = 1.0;
    Jc[1] = 0.0;
    Jc[2] = J1x + J2x;
    Jc[3] = J1x + J2x;
    Jc[4] = J2x;
    Jc[5] = 0.0;
    Jc[6] = 1.0;
    Jc[7] = J1y + J2y;
    Jc[8] = J1y + J2y;
    Jc[9] = J2y;
}

/* The contact Jacobian Jc = d p_f / d q (section 3, Problem 3), 2x5 row-major. */
static void jacobian_one(const leg_params *P, const double *q, double *Jc)
{
    const double th1 = q[2] + q[3], th2 = th1 + q[4];
    jacobian_trig(P, sin(th1), cos(th1), sin(th2), cos(th2), Jc);
}

/* Jcdot(q, qd) qd, the foot's velocity-product acceleration. */
static void jdot_qd_one(const leg_params *P, const double *q, const double *qd, double *out)
{
    const double th1 = q[2] + q[3], th2 = th1 + q[4];
    const double w1 = qd[2] + qd[3], w2 = w1 + qd[4];
    out[0] = -P->l1 * cos(th1) * w1 * w1 - P->l2 * cos(th2) * w2 * w2;
    out[1] = -P->l1 * sin(th1) * w1 * w1 - P->l2 * sin(th2) * w2 * w2;
}

/* The whole-body centre of mass and its velocity (world frame; vel may be NULL) from the link angles'
 * sines/cosines. */
static inline void com_trig(const leg_params *P, const double *q, const double *qd, double s1, double co1, double s2,
                            double co2, double *pos, double *vel)
{
    const double m = P->m_b + P->m1 + P->m2, a = P->m1 * P->c1 + P->m2 * P->l1, b = P->m2 * P->c2;
    pos[0] = q[0] + (a * co1 + b * co2) / m;
    pos[1] = q[1] + (a * s1 + b * s2) / m;
    if (vel) {
        const double w1 = qd[2] + qd[3], w2 = w1 + qd[4];
        vel[0] = qd[0] - (a * s1 * w1 + b * s2 * w2) / m;
        vel[1] = qd[1] + (a * co1 * w1 + b * co2 * w2) / m;
    }
}

/* The whole-body centre of mass and its velocity (world frame). */
static void com_one(const leg_params *P, const double *q, const double *qd, double *pos, double *vel)
{
    const double th1 = q[2] + q[3], th2 = th1 + q[4];
    com_trig(P, q, qd, sin(th1), cos(th1), sin(th2), cos(th2), pos, vel);
}

/* The stance equilibrium with the torso level, the knee at `knee` and the COM above the foot at the
 * origin: its posture q and holding torques tau (M qdd + G = S^T tau + Jc^T lam with qdd = 0 and
 * lam = (0, m g), read on the actuated rows); trig (NULL or 4 doubles) gets sin th1, cos th1, sin th2,
 * cos th2 of q, computed once for all of it. */
static void equilibrium_one(const leg_params *P, double knee, double *q, double *tau, double *trig)
{
    const double m = P->m_b + P->m1 + P->m2;
    const double A = (P->m1 * P->c1 + P->m2 * P->l1) / m - P->l1;
    const double B = P->m2 * P->c2 / m - P->l2;
    double th1 = atan2(A + B * cos(knee), B * sin(knee));
    while (th1 > 0.0)
        th1 -= M_PI;
    while (th1 <= -M_PI)
        th1 += M_PI;
    q[0] = 0.0;
    q[1] = 0.0;
    q[2] = 0.0;
    q[3] = th1;
    q[4] = knee;
    const double a1 = q[2] + q[3], a2 = a1 + q[4]; /* the link angles, as foot_one() forms them */
    const double s1 = sin(a1), co1 = cos(a1), s2 = sin(a2), co2 = cos(a2);
    double foot[2], G[LEG_NQ], Jc[2 * LEG_NQ];
    foot_trig(P, q[0], q[1], s1, co1, s2, co2, foot);
    q[0] -= foot[0];
    q[1] -= foot[1];
    bias_trig(P, s1, co1, s2, co2, sin(a1 - a2), 0.0, 0.0, G); /* gravity alone */
    jacobian_trig(P, s1, co1, s2, co2, Jc);
    const double mg = m * P->g;
    tau[0] = G[3] - (Jc[3] * 0.0 + Jc[LEG_NQ + 3] * mg);
    tau[1] = G[4] - (Jc[4] * 0.0 + Jc[LEG_NQ + 4] * mg);
    if (trig) {
        trig[0] = s1;
        trig[1] = co1;
        trig[2] = s2;
        trig[3] = co2;
    }
}
