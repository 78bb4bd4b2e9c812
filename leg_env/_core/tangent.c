/* Derivatives of the control step as computed (leg_env.physics.derivatives documents them for users).
 *
 * Forward mode: a tangent matrix T, d(state)/d(direction), rides along the step. Its directions are the state's
 * ten, x = (q, qd) = (x_b, y_b, th_b, q1, q2, x_b', y_b', th_b', q1', q2'), then the two torques. Every RK4 substep
 * maps T by the derivative of that substep (its four stages at their own states, then the mode's projection), so
 * that the product is the derivative of the discrete map the step computes, with its substep count held.
 *
 * A mode's accelerations and contact force depend on the state only through the leg's absolute angles and rates
 * z = (th1, th2, w1, w2) (the base's position and velocity do not enter: translation invariance; the torso turns
 * under -tau_hip / I_b alone), and on the torques: one partial matrix D = d(xdd, ydd, thbdd, q1dd, q2dd, lam_x,
 * lam_y) / d(th1, th2, w1, w2, tau_hip, tau_knee) per stage, formed by differentiating the mode's 2x2 solve
 * (dynamics.c): K dd = r gives K d(dd) = dr - dK dd, solved with K's own factorisation.
 *
 * Part of the unity build of module.c.
 */
#include <math.h>

#include "robot.h"

#define LEG_NX 10              /* the state (q, qd) */
#define LEG_ND (LEG_NX + LEG_NU) /* tangent directions: the state's, then the torques' */
#define LEG_NZ 6               /* what a mode's dynamics depend on: th1, th2, w1, w2, tau_hip, tau_knee */

enum { IX = 0, IY, IA, IB, IC, IVX, IVY, IVA, IVB, IVC }; /* rows of a tangent: leg_x's fields, in order */

/* d(xdd, ydd, thbdd, q1dd, q2dd, lam_x, lam_y) / dz at one state of one mode. */
typedef struct {
    double d[7][LEG_NZ];
} leg_partials;

/* d(state) / d(direction): one row per state entry, one column per direction. */
typedef struct {
    double t[LEG_NX][LEG_ND];
} leg_tangent;

/* The partials of the leg's link accelerations from the 2x2 solve K dd = r, K = [[K11, K12], [K12, K22]] with
 * K12 = kap cos(th1 - th2): R1, R2 are dr/dz, and (vx, vy) = d^2/dt^2 (cos th1, sin th1) rotated as in stance_m:
 * vx = co1 w1^2 + s1 dd1, vy = s1 w1^2 - co1 dd1, ux, uy likewise for th2. Writes d(dd1, dd2) and d(vx, vy, ux, uy). */
static inline void link_partials(double K11, double K22, double kap, double s1, double co1, double s2, double co2, double w1,
                                 double w2, double dd1, double dd2, const double *R1, const double *R2, double *Ddd1,
                                 double *Ddd2, double *Dvx, double *Dvy, double *Dux, double *Duy)
{
    const double c12 = co1 * co2 + s1 * s2, s12 = s1 * co2 - co1 * s2;
    const double K12 = kap * c12;
    const double inv_det = 1.0 / (K11 * K22 - K12 * K12);
    const double dK12[LEG_NZ] = {-kap * s12, kap * s12, 0.0, 0.0, 0.0, 0.0}; /* d cos(th1 - th2) = -s12 (dth1 - dth2) */
    for (int j = 0; j < LEG_NZ; j++) {
        const double rhs1 = R1[j] - dK12[j] * dd2, rhs2 = R2[j] - dK12[j] * dd1;
        Ddd1[j] = (K22 * rhs1 - K12 * rhs2) * inv_det;
        Ddd2[j] = (K11 * rhs2 - K12 * rhs1) * inv_det;
        Dvx[j] = s1 * Ddd1[j];
        Dvy[j] = -co1 * Ddd1[j];
        Dux[j] = s2 * Ddd2[j];
        Duy[j] = -co2 * Ddd2[j];
    }
    const double v1 = w1 * w1, v2 = w2 * w2;
    Dvx[0] += -s1 * v1 + co1 * dd1;
    Dvy[0] += co1 * v1 + s1 * dd1;
    Dvx[2] += 2.0 * co1 * w1;
    Dvy[2] += 2.0 * s1 * w1;
    Dux[1] += -s2 * v2 + co2 * dd2;
    Duy[1] += co2 * v2 + s2 * dd2;
    Dux[3] += 2.0 * co2 * w2;
    Duy[3] += 2.0 * s2 * w2;
}

/* stance_m's accelerations and their partials. */
static inline leg_accel stance_partials(const leg_model *M, double s1, double co1, double s2, double co2, double w1,
                                        double w2, double tau_hip, double tau_knee, double F, leg_partials *D)
{
    const leg_accel A = stance_m(M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
    const double l1 = M->p.l1, l2 = M->p.l2, g = M->p.g, e1 = M->e1, e2 = M->e2, kap = M->kap;
    const double c12 = co1 * co2 + s1 * s2, s12 = s1 * co2 - co1 * s2, v1 = w1 * w1, v2 = w2 * w2;
    /* r1 = tau_hip - tau_knee + g e1 co1 - kap s12 w2^2 + F l1 s1,  r2 = tau_knee + g e2 co2 + kap s12 w1^2 + F l2 s2 */
    const double R1[LEG_NZ] = {-g * e1 * s1 - kap * c12 * v2 + F * l1 * co1, kap * c12 * v2, 0.0, -2.0 * kap * s12 * w2, 1.0, -1.0};
    const double R2[LEG_NZ] = {kap * c12 * v1, -g * e2 * s2 - kap * c12 * v1 + F * l2 * co2, 2.0 * kap * s12 * w1, 0.0, 0.0, 1.0};
    const double dd1 = A.q1dd + A.thbdd, dd2 = A.q2dd + dd1;
    double Ddd1[LEG_NZ], Ddd2[LEG_NZ], Dvx[LEG_NZ], Dvy[LEG_NZ], Dux[LEG_NZ], Duy[LEG_NZ];
    link_partials(M->K11s, M->K22s, kap, s1, co1, s2, co2, w1, w2, dd1, dd2, R1, R2, Ddd1, Ddd2, Dvx, Dvy, Dux, Duy);
    for (int j = 0; j < LEG_NZ; j++) {
        const double dthb = j == 4 ? -1.0 / M->p.I_b : 0.0;
        D->d[0][j] = l1 * Dvx[j] + l2 * Dux[j];
        D->d[1][j] = l1 * Dvy[j] + l2 * Duy[j];
        D->d[2][j] = dthb;
        D->d[3][j] = Ddd1[j] - dthb;
        D->d[4][j] = Ddd2[j] - Ddd1[j];
        D->d[5][j] = e1 * Dvx[j] + e2 * Dux[j];
        D->d[6][j] = e1 * Dvy[j] + e2 * Duy[j];
    }
    return A;
}

/* flight_m's accelerations and their partials. */
static inline leg_accel flight_partials(const leg_model *M, double s1, double co1, double s2, double co2, double w1,
                                        double w2, double tau_hip, double tau_knee, double F, leg_partials *D)
{
    const leg_accel A = flight_m(M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
    const double m = M->m, a = M->a, b = M->b, kf = M->kf;
    const double c12 = co1 * co2 + s1 * s2, s12 = s1 * co2 - co1 * s2, v1 = w1 * w1, v2 = w2 * w2;
    /* r1 = tau_hip - tau_knee - kf s12 w2^2 + F a s1 / m,  r2 = tau_knee + kf s12 w1^2 + F b s2 / m */
    const double R1[LEG_NZ] = {-kf * c12 * v2 + F * a * co1 / m, kf * c12 * v2, 0.0, -2.0 * kf * s12 * w2, 1.0, -1.0};
    const double R2[LEG_NZ] = {kf * c12 * v1, -kf * c12 * v1 + F * b * co2 / m, 2.0 * kf * s12 * w1, 0.0, 0.0, 1.0};
    const double dd1 = A.q1dd + A.thbdd, dd2 = A.q2dd + dd1;
    double Ddd1[LEG_NZ], Ddd2[LEG_NZ], Dvx[LEG_NZ], Dvy[LEG_NZ], Dux[LEG_NZ], Duy[LEG_NZ];
    link_partials(M->K11f, M->K22f, kf, s1, co1, s2, co2, w1, w2, dd1, dd2, R1, R2, Ddd1, Ddd2, Dvx, Dvy, Dux, Duy);
    for (int j = 0; j < LEG_NZ; j++) {
        const double dthb = j == 4 ? -1.0 / M->p.I_b : 0.0;
        D->d[0][j] = (a * Dvx[j] + b * Dux[j]) / m;
        D->d[1][j] = (a * Dvy[j] + b * Duy[j]) / m;
        D->d[2][j] = dthb;
        D->d[3][j] = Ddd1[j] - dthb;
        D->d[4][j] = Ddd2[j] - Ddd1[j];
        D->d[5][j] = 0.0;
        D->d[6][j] = 0.0;
    }
    return A;
}

/* The partials of the mode `mode` (stick or flight). */
static inline leg_accel mode_partials(int mode, const leg_model *M, const leg_drive *u, double s1, double co1, double s2,
                                      double co2, double w1, double w2, leg_partials *D)
{
    if (mode == LEG_STICK)
        return stance_partials(M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x, D);
    return flight_partials(M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x, D);
}

/* One RK4 stage's derivative k = (qd, qdd) and its tangent dk = (dS's rates, D dz), for the stage's state tangent dS.
 * dtau: the torques' tangent (rows tau_hip, tau_knee). */
static inline void stage_tangent(const leg_partials *D, const leg_tangent *dS, const double dtau[LEG_NU][LEG_ND],
                                 leg_tangent *dk)
{
    for (int i = 0; i < LEG_NQ; i++)
        for (int j = 0; j < LEG_ND; j++)
            dk->t[i][j] = dS->t[IVX + i][j];
    for (int j = 0; j < LEG_ND; j++) {
        const double dth1 = dS->t[IA][j] + dS->t[IB][j], dth2 = dth1 + dS->t[IC][j];
        const double dw1 = dS->t[IVA][j] + dS->t[IVB][j], dw2 = dw1 + dS->t[IVC][j];
        const double dz[LEG_NZ] = {dth1, dth2, dw1, dw2, dtau[0][j], dtau[1][j]};
        for (int r = 0; r < LEG_NQ; r++) {
            double s = 0.0;
            for (int k = 0; k < LEG_NZ; k++)
                s += D->d[r][k] * dz[k];
            dk->t[IVX + r][j] = s;
        }
    }
}

/* out = a + c b, entry by entry. */
static inline void tangent_axpy(const leg_tangent *a, double c, const leg_tangent *b, leg_tangent *out)
{
    for (int i = 0; i < LEG_NX; i++)
        for (int j = 0; j < LEG_ND; j++)
            out->t[i][j] = a->t[i][j] + c * b->t[i][j];
}

/* The contact's projection (rk4_substep's) on the tangent of a substep's end state Y: in stick the base follows the
 * anchor and the leg, x_b = anchor_x - l1 co1 - l2 co2 and likewise y_b, (x_b, y_b)' = -(dp_f / d th) th'; in slip only
 * y_b and y_b'. danchor: the anchor's tangent (rows x, y). */
static inline void project_tangent(int mode, const leg_params *P, const leg_x *Y, const double danchor[2][LEG_ND],
                                   leg_tangent *T)
{
    if (mode == LEG_FLIGHT)
        return;
    const double l1 = P->l1, l2 = P->l2, s1 = Y->s1, co1 = Y->c1, s2 = Y->s2, co2 = Y->c2;
    const double w1 = Y->va + Y->vb, w2 = w1 + Y->vc;
    for (int j = 0; j < LEG_ND; j++) {
        const double dth1 = T->t[IA][j] + T->t[IB][j], dth2 = dth1 + T->t[IC][j];
        const double dw1 = T->t[IVA][j] + T->t[IVB][j], dw2 = dw1 + T->t[IVC][j];
        T->t[IY][j] = danchor[1][j] - l1 * co1 * dth1 - l2 * co2 * dth2;
        T->t[IVY][j] = l1 * (s1 * w1 * dth1 - co1 * dw1) + l2 * (s2 * w2 * dth2 - co2 * dw2);
        if (mode == LEG_STICK) {
            T->t[IX][j] = danchor[0][j] + l1 * s1 * dth1 + l2 * s2 * dth2;
            T->t[IVX][j] = l1 * (co1 * w1 * dth1 + s1 * dw1) + l2 * (co2 * w2 * dth2 + s2 * dw2);
        }
    }
}

/* The tangent of rk4_substep(mode, M, u, anchor, X, k1, h): T in, the end state's tangent out (in place). Y is the
 * substep's end state (rk4_substep's). The stages are rk4_substep's, at the same states. */
static void rk4_substep_tangent(int mode, const leg_model *M, const leg_drive *u, const leg_x *X, double h, const leg_x *Y,
                                const double dtau[LEG_NU][LEG_ND], const double danchor[2][LEG_ND], leg_tangent *T)
{
    const double ch = RK4_HALF * h;
    leg_partials D;
    leg_tangent dk1, dk2, dk3, dk4, dS;
    double S1, C1, S2, C2;
    /* stage 1 at X */
    const double w1 = X->va + X->vb, w2 = w1 + X->vc;
    const leg_accel k1 = mode_partials(mode, M, u, X->s1, X->c1, X->s2, X->c2, w1, w2, &D);
    stage_tangent(&D, T, dtau, &dk1);
    /* stage 2 at X + h/2 k1 */
    const double va2 = X->va + ch * k1.thbdd, vb2 = X->vb + ch * k1.q1dd, vc2 = X->vc + ch * k1.q2dd;
    turn(X->s1, X->c1, ch * w1, &S1, &C1);
    turn(X->s2, X->c2, ch * w2, &S2, &C2);
    const double w1_2 = va2 + vb2, w2_2 = w1_2 + vc2;
    const leg_accel k2 = mode_partials(mode, M, u, S1, C1, S2, C2, w1_2, w2_2, &D);
    tangent_axpy(T, ch, &dk1, &dS);
    stage_tangent(&D, &dS, dtau, &dk2);
    /* stage 3 at X + h/2 k2 */
    const double va3 = X->va + ch * k2.thbdd, vb3 = X->vb + ch * k2.q1dd, vc3 = X->vc + ch * k2.q2dd;
    turn(X->s1, X->c1, ch * w1_2, &S1, &C1);
    turn(X->s2, X->c2, ch * w2_2, &S2, &C2);
    const double w1_3 = va3 + vb3, w2_3 = w1_3 + vc3;
    const leg_accel k3 = mode_partials(mode, M, u, S1, C1, S2, C2, w1_3, w2_3, &D);
    tangent_axpy(T, ch, &dk2, &dS);
    stage_tangent(&D, &dS, dtau, &dk3);
    /* stage 4 at X + h k3 */
    const double va4 = X->va + h * k3.thbdd, vb4 = X->vb + h * k3.q1dd, vc4 = X->vc + h * k3.q2dd;
    turn(X->s1, X->c1, h * w1_3, &S1, &C1);
    turn(X->s2, X->c2, h * w2_3, &S2, &C2);
    (void)mode_partials(mode, M, u, S1, C1, S2, C2, va4 + vb4, va4 + vb4 + vc4, &D);
    tangent_axpy(T, h, &dk3, &dS);
    stage_tangent(&D, &dS, dtau, &dk4);
    /* y1 = y0 + h (k1 + 2 k2 + 2 k3 + k4) / 6 */
    for (int i = 0; i < LEG_NX; i++)
        for (int j = 0; j < LEG_ND; j++)
            T->t[i][j] += h * (RK4_W0 * (dk1.t[i][j] + dk4.t[i][j]) + RK4_W1 * (dk2.t[i][j] + dk3.t[i][j]));
    project_tangent(mode, &M->p, Y, danchor, T);
}

/* rk4_control_step() of one robot with its derivatives (row-major): A = d(q, qd) after / d(q, qd) before, (10, 10),
 * and B = d(q, qd) after / d(tau_hip, tau_knee), (10, 2). follow: the anchor is the foot of the state before the step
 * (stance_step's default), so that it moves with q; else it is held. Returns the RK4 steps taken. */
static int rk4_control_jacobians(const leg_params *P, const leg_drive *u, double *q, double *qd, const double *anchor,
                                 double dt, int substeps, double max_angle, int stance, int follow, double s1, double co1,
                                 double s2, double co2, double *lam_mean, double *A, double *B)
{
    const int n = substeps_for_rates(qd[2], qd[3], qd[4], dt, substeps, max_angle);
    const double h = dt / n;
    const int mode = stance ? LEG_STICK : LEG_FLIGHT;
    leg_model M;
    model_init(&M, P);
    leg_x X = x_from(q, qd, s1, co1, s2, co2);
    leg_tangent T;
    memset(&T, 0, sizeof T);
    for (int i = 0; i < LEG_NX; i++)
        T.t[i][i] = 1.0;
    double dtau[LEG_NU][LEG_ND] = {{0.0}}, danchor[2][LEG_ND] = {{0.0}};
    dtau[0][LEG_NX] = 1.0;
    dtau[1][LEG_NX + 1] = 1.0;
    if (stance && follow) { /* anchor = p_f(q) = (x_b, y_b) + l1 (co1, s1) + l2 (co2, s2) */
        const double l1 = P->l1, l2 = P->l2;
        danchor[0][IX] = 1.0;
        danchor[1][IY] = 1.0;
        danchor[0][IA] = danchor[0][IB] = -l1 * s1 - l2 * s2;
        danchor[1][IA] = danchor[1][IB] = l1 * co1 + l2 * co2;
        danchor[0][IC] = -l2 * s2;
        danchor[1][IC] = l2 * co2;
    }
    leg_sums sums = {0.0, 0.0, 0.0};
    for (int i = 0; i < n; i++) {
        const leg_accel k1 = derivative(mode, &M, u, &X);
        const leg_x Y = rk4_substep(mode, &M, u, anchor, &X, &k1, h, &sums);
        rk4_substep_tangent(mode, &M, u, &X, h, &Y, dtau, danchor, &T);
        X = Y;
    }
    x_to(&X, q, qd);
    lam_mean[0] = sums.lx / n;
    lam_mean[1] = sums.ly / n;
    for (int i = 0; i < LEG_NX; i++) {
        for (int j = 0; j < LEG_NX; j++)
            A[i * LEG_NX + j] = T.t[i][j];
        for (int j = 0; j < LEG_NU; j++)
            B[i * LEG_NU + j] = T.t[i][LEG_NX + j];
    }
    return n;
}
