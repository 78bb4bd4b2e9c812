/* Derivatives of the control step as computed (leg_env.physics.derivatives documents them for users).
 *
 * Forward mode: a tangent matrix T, d(state)/d(direction), rides along the step. Its directions are the state's
 * ten, x = (q, qd) = (x_b, y_b, th_b, q1, q2, x_b', y_b', th_b', q1', q2'), then the two torques, then (where the
 * parameters' Jacobian is asked for) the robot's eleven parameters (LegParams' fields in order) and the friction
 * coefficient mu. Every RK4 substep maps T by the derivative of that substep (its four stages at their own states,
 * then the mode's projection), so that the product is the derivative of the discrete map the step computes, with
 * its substep count held.
 *
 * A mode's accelerations and contact force depend on the state only through the leg's absolute angles and rates
 * (the base's position and velocity do not enter: translation invariance; the torso turns under -tau_hip / I_b
 * alone): one partial matrix D = d(xdd, ydd, thbdd, q1dd, q2dd, lam_x, lam_y) / dz per stage, z = (th1, th2, w1, w2,
 * tau_hip, tau_knee, the parameters, mu), formed by differentiating the mode's 2x2 solve (dynamics.c): K dd = r gives
 * K d(dd) = dr - dK dd, solved with K's own factorisation. The parameters enter through the model's constants
 * (leg_model), differentiated once per direction (model_tangent).
 *
 * Part of the unity build of module.c.
 */
#include <math.h>

#include "robot.h"

#define LEG_NX 10                         /* the state (q, qd) */
#define LEG_NPD (LEG_N_PARAMS + 1)        /* parameter directions: LegParams' fields, then mu */
#define LEG_ND (LEG_NX + LEG_NU)          /* the directions of A and B: the state's, then the torques' */
#define LEG_NDP (LEG_ND + LEG_NPD)        /* and of P: the parameters' */
#define LEG_NT (LEG_NDP + 1)              /* the columns: the directions, and one for a substep whose length an event sets */
#define LEG_NZ0 6                         /* what a mode's dynamics depend on: th1, th2, w1, w2, tau_hip, tau_knee */
#define LEG_NZ (LEG_NZ0 + LEG_NPD)        /* and the parameters and mu */
#define LEG_MU_DIR (LEG_NZ0 + LEG_N_PARAMS) /* mu's entry of z */

enum { IX = 0, IY, IA, IB, IC, IVX, IVY, IVA, IVB, IVC }; /* rows of a tangent: leg_x's fields, in order */
enum { PL1 = 6, PL2 = 7 };                                /* l1's and l2's index among LegParams' fields */

/* d(xdd, ydd, thbdd, q1dd, q2dd, lam_x, lam_y) / dz at one state of one mode (the first nz columns of z). */
typedef struct {
    double d[7][LEG_NZ];
} leg_partials;

/* d(state) / d(direction): one row per state entry, one column per direction (the first nc of LEG_NT in use). */
typedef struct {
    double t[LEG_NX][LEG_NT];
} leg_tangent;

/* The parameter direction k of column j of a tangent (-1: the column is a state's, a torque's or the scratch one). */
static inline int param_of(int j) { return j >= LEG_ND && j < LEG_NDP ? j - LEG_ND : -1; }

/* The derivatives of a robot's model constants (leg_model's, from model_init) along parameter direction k
 * (LegParams' fields, then mu at LEG_N_PARAMS). */
typedef struct {
    double m, inv_m, a, b, kf, K11f, K22f, e1, e2, kap, K11s, K22s, al1, al2; /* the derived constants */
    double I_b, l1, l2, g, mu;                                                  /* the parameters used as they are */
} leg_model_d;

static leg_model_d model_tangent(const leg_model *M, int k)
{
    leg_model_d d;
    memset(&d, 0, sizeof d);
    if (k == LEG_N_PARAMS) {
        d.mu = 1.0;
        return d;
    }
    double dp[LEG_N_PARAMS] = {0.0};
    dp[k] = 1.0;
    const double dm_b = dp[0], dm1 = dp[1], dm2 = dp[2], dI_b = dp[3], dI1 = dp[4], dI2 = dp[5], dl1 = dp[6], dl2 = dp[7];
    const double dc1 = dp[8], dc2 = dp[9], dg = dp[10];
    const leg_params *P = &M->p;
    const double m_b = P->m_b, m1 = P->m1, m2 = P->m2, l1 = P->l1, l2 = P->l2, c1 = P->c1, c2 = P->c2;
    const double m = M->m, a = M->a, b = M->b, mm = m * m;
    d.m = dm_b + dm1 + dm2;
    d.inv_m = -d.m / mm;
    d.a = dm1 * c1 + m1 * dc1 + dm2 * l1 + m2 * dl1;
    d.b = dm2 * c2 + m2 * dc2;
    d.kf = dm2 * l1 * c2 + m2 * dl1 * c2 + m2 * l1 * dc2 - (d.a * b + a * d.b) / m + a * b * d.m / mm;
    d.K11f = dI1 + dm1 * c1 * c1 + 2.0 * m1 * c1 * dc1 + dm2 * l1 * l1 + 2.0 * m2 * l1 * dl1 - 2.0 * a * d.a / m + a * a * d.m / mm;
    d.K22f = dI2 + dm2 * c2 * c2 + 2.0 * m2 * c2 * dc2 - 2.0 * b * d.b / m + b * b * d.m / mm;
    d.e1 = dm_b * l1 + m_b * dl1 + dm1 * (l1 - c1) + m1 * (dl1 - dc1);
    d.e2 = (dm_b + dm1) * l2 + (m_b + m1) * dl2 + dm2 * (l2 - c2) + m2 * (dl2 - dc2);
    d.kap = dl2 * M->e1 + l2 * d.e1;
    d.K11s = dI1 + dm1 * (l1 - c1) * (l1 - c1) + 2.0 * m1 * (l1 - c1) * (dl1 - dc1) + dm_b * l1 * l1 + 2.0 * m_b * l1 * dl1;
    d.K22s = dI2 + dm2 * (l2 - c2) * (l2 - c2) + 2.0 * m2 * (l2 - c2) * (dl2 - dc2) + (dm_b + dm1) * l2 * l2 + 2.0 * (m_b + m1) * l2 * dl2;
    d.al1 = dl1 - d.a / m + a * d.m / mm;
    d.al2 = dl2 - d.b / m + b * d.m / mm;
    d.I_b = dI_b;
    d.l1 = dl1;
    d.l2 = dl2;
    d.g = dg;
    return d;
}

/* The partials of the leg's link accelerations from the 2x2 solve K dd = r, K = [[K11, K12], [K12, K22]] with
 * K12 = kap cos(th1 - th2), over the first nz entries of z: R1, R2 are dr/dz, dK11, dK22, dkap the constants'
 * derivatives (zero for the state's and the torques' entries); (vx, vy) = co1 w1^2 + s1 dd1, s1 w1^2 - co1 dd1 as in
 * stance_m, (ux, uy) likewise for th2. Writes d(dd1, dd2) and d(vx, vy, ux, uy). */
LEG_INLINE void link_partials(int nz, double K11, double K22, double kap, double s1, double co1, double s2, double co2,
                                 double w1, double w2, double dd1, double dd2, const double *R1, const double *R2,
                                 const double *dK11, const double *dK22, const double *dkap, double *Ddd1, double *Ddd2,
                                 double *Dvx, double *Dvy, double *Dux, double *Duy)
{
    const double c12 = co1 * co2 + s1 * s2, s12 = s1 * co2 - co1 * s2;
    const double K12 = kap * c12;
    const double inv_det = 1.0 / (K11 * K22 - K12 * K12);
    for (int j = 0; j < nz; j++) {
        const double dc12 = j == 0 ? -s12 : (j == 1 ? s12 : 0.0); /* d cos(th1 - th2) = -s12 (dth1 - dth2) */
        const double dK12 = dkap[j] * c12 + kap * dc12;
        const double rhs1 = R1[j] - dK11[j] * dd1 - dK12 * dd2, rhs2 = R2[j] - dK12 * dd1 - dK22[j] * dd2;
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

/* The torso's and the joints' rows of D from d(dd1, dd2): th_b'' = -tau_hip / I_b, q1'' = dd1 - th_b'',
 * q2'' = dd2 - dd1. */
LEG_INLINE void joint_rows(int nz, const leg_model *M, double tau_hip, const double *Ddd1, const double *Ddd2,
                              leg_partials *D)
{
    const double I_b = M->p.I_b;
    for (int j = 0; j < nz; j++) {
        double dthb = j == 4 ? -1.0 / I_b : 0.0;
        if (j == LEG_NZ0 + 3) /* I_b */
            dthb = tau_hip / (I_b * I_b);
        D->d[2][j] = dthb;
        D->d[3][j] = Ddd1[j] - dthb;
        D->d[4][j] = Ddd2[j] - Ddd1[j];
    }
}

/* stance_m's accelerations and their partials over the first nz entries of z. */
LEG_INLINE leg_accel stance_partials(int nz, const leg_model *M, double s1, double co1, double s2, double co2, double w1,
                                        double w2, double tau_hip, double tau_knee, double F, leg_partials *D)
{
    const leg_accel A = stance_m(M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
    const double l1 = M->p.l1, l2 = M->p.l2, g = M->p.g, m = M->m, e1 = M->e1, e2 = M->e2, kap = M->kap;
    const double c12 = co1 * co2 + s1 * s2, s12 = s1 * co2 - co1 * s2, v1 = w1 * w1, v2 = w2 * w2;
    /* r1 = tau_hip - tau_knee + g e1 co1 - kap s12 w2^2 + F l1 s1,  r2 = tau_knee + g e2 co2 + kap s12 w1^2 + F l2 s2 */
    const double r1[LEG_NZ0] = {-g * e1 * s1 - kap * c12 * v2 + F * l1 * co1, kap * c12 * v2, 0.0, -2.0 * kap * s12 * w2, 1.0, -1.0};
    const double r2[LEG_NZ0] = {kap * c12 * v1, -g * e2 * s2 - kap * c12 * v1 + F * l2 * co2, 2.0 * kap * s12 * w1, 0.0, 0.0, 1.0};
    double R1[LEG_NZ], R2[LEG_NZ], dK11[LEG_NZ], dK22[LEG_NZ], dkap[LEG_NZ];
    for (int j = 0; j < LEG_NZ0; j++) {
        R1[j] = r1[j];
        R2[j] = r2[j];
        dK11[j] = dK22[j] = dkap[j] = 0.0;
    }
    leg_model_d dM[LEG_NPD];
    for (int k = 0; LEG_NZ0 + k < nz; k++) {
        const leg_model_d d = dM[k] = model_tangent(M, k);
        const int j = LEG_NZ0 + k;
        R1[j] = d.g * e1 * co1 + g * d.e1 * co1 - d.kap * s12 * v2 + F * d.l1 * s1;
        R2[j] = d.g * e2 * co2 + g * d.e2 * co2 + d.kap * s12 * v1 + F * d.l2 * s2;
        dK11[j] = d.K11s;
        dK22[j] = d.K22s;
        dkap[j] = d.kap;
    }
    const double dd1 = A.q1dd + A.thbdd, dd2 = A.q2dd + dd1;
    const double vx = co1 * v1 + s1 * dd1, vy = s1 * v1 - co1 * dd1, ux = co2 * v2 + s2 * dd2, uy = s2 * v2 - co2 * dd2;
    double Ddd1[LEG_NZ], Ddd2[LEG_NZ], Dvx[LEG_NZ], Dvy[LEG_NZ], Dux[LEG_NZ], Duy[LEG_NZ];
    link_partials(nz, M->K11s, M->K22s, kap, s1, co1, s2, co2, w1, w2, dd1, dd2, R1, R2, dK11, dK22, dkap, Ddd1, Ddd2, Dvx,
                  Dvy, Dux, Duy);
    for (int j = 0; j < nz; j++) {
        D->d[0][j] = l1 * Dvx[j] + l2 * Dux[j];
        D->d[1][j] = l1 * Dvy[j] + l2 * Duy[j];
        D->d[5][j] = e1 * Dvx[j] + e2 * Dux[j];
        D->d[6][j] = e1 * Dvy[j] + e2 * Duy[j];
        if (j >= LEG_NZ0) { /* xdd = l1 vx + l2 ux, lam = e1 (vx, vy) + e2 (ux, uy) + (-F, m g) */
            const leg_model_d *d = &dM[j - LEG_NZ0];
            D->d[0][j] += d->l1 * vx + d->l2 * ux;
            D->d[1][j] += d->l1 * vy + d->l2 * uy;
            D->d[5][j] += d->e1 * vx + d->e2 * ux;
            D->d[6][j] += d->e1 * vy + d->e2 * uy + d->m * g + m * d->g;
        }
    }
    joint_rows(nz, M, tau_hip, Ddd1, Ddd2, D);
    return A;
}

/* The flight solve's right-hand side partials (r1 = tau_hip - tau_knee - kf s12 w2^2 + F a s1 / m, r2 = tau_knee +
 * kf s12 w1^2 + F b s2 / m) and its constants' (K11f, K22f, kf), over the first nz entries of z. */
LEG_INLINE void flight_rhs(int nz, const leg_model *M, double s1, double co1, double s2, double co2, double w1, double w2,
                              double F, const leg_model_d *dM, double *R1, double *R2, double *dK11, double *dK22, double *dkf)
{
    const double m = M->m, a = M->a, b = M->b, kf = M->kf;
    const double c12 = co1 * co2 + s1 * s2, s12 = s1 * co2 - co1 * s2, v1 = w1 * w1, v2 = w2 * w2;
    const double r1[LEG_NZ0] = {-kf * c12 * v2 + F * a * co1 / m, kf * c12 * v2, 0.0, -2.0 * kf * s12 * w2, 1.0, -1.0};
    const double r2[LEG_NZ0] = {kf * c12 * v1, -kf * c12 * v1 + F * b * co2 / m, 2.0 * kf * s12 * w1, 0.0, 0.0, 1.0};
    for (int j = 0; j < nz; j++) {
        if (j < LEG_NZ0) {
            R1[j] = r1[j];
            R2[j] = r2[j];
            dK11[j] = dK22[j] = dkf[j] = 0.0;
            continue;
        }
        const leg_model_d *d = &dM[j - LEG_NZ0];
        R1[j] = -d->kf * s12 * v2 + F * s1 * (d->a / m - a * d->m / (m * m));
        R2[j] = d->kf * s12 * v1 + F * s2 * (d->b / m - b * d->m / (m * m));
        dK11[j] = d->K11f;
        dK22[j] = d->K22f;
        dkf[j] = d->kf;
    }
}

/* flight_m's accelerations and their partials over the first nz entries of z. */
LEG_INLINE leg_accel flight_partials(int nz, const leg_model *M, double s1, double co1, double s2, double co2, double w1,
                                        double w2, double tau_hip, double tau_knee, double F, leg_partials *D)
{
    const leg_accel A = flight_m(M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
    const double m = M->m, a = M->a, b = M->b, v1 = w1 * w1, v2 = w2 * w2;
    leg_model_d dM[LEG_NPD];
    for (int k = 0; LEG_NZ0 + k < nz; k++)
        dM[k] = model_tangent(M, k);
    double R1[LEG_NZ], R2[LEG_NZ], dK11[LEG_NZ], dK22[LEG_NZ], dkf[LEG_NZ];
    flight_rhs(nz, M, s1, co1, s2, co2, w1, w2, F, dM, R1, R2, dK11, dK22, dkf);
    const double dd1 = A.q1dd + A.thbdd, dd2 = A.q2dd + dd1;
    const double vx = co1 * v1 + s1 * dd1, vy = s1 * v1 - co1 * dd1, ux = co2 * v2 + s2 * dd2, uy = s2 * v2 - co2 * dd2;
    double Ddd1[LEG_NZ], Ddd2[LEG_NZ], Dvx[LEG_NZ], Dvy[LEG_NZ], Dux[LEG_NZ], Duy[LEG_NZ];
    link_partials(nz, M->K11f, M->K22f, M->kf, s1, co1, s2, co2, w1, w2, dd1, dd2, R1, R2, dK11, dK22, dkf, Ddd1, Ddd2, Dvx,
                  Dvy, Dux, Duy);
    for (int j = 0; j < nz; j++) {
        D->d[0][j] = (a * Dvx[j] + b * Dux[j]) / m;
        D->d[1][j] = (a * Dvy[j] + b * Duy[j]) / m;
        D->d[5][j] = 0.0;
        D->d[6][j] = 0.0;
        if (j >= LEG_NZ0) { /* xdd = (a vx + b ux + F) / m, ydd = (a vy + b uy) / m - g */
            const leg_model_d *d = &dM[j - LEG_NZ0];
            D->d[0][j] += (d->a * vx + d->b * ux) / m - (a * vx + b * ux + F) * d->m / (m * m);
            D->d[1][j] += (d->a * vy + d->b * uy) / m - (a * vy + b * uy) * d->m / (m * m) - d->g;
        }
    }
    joint_rows(nz, M, tau_hip, Ddd1, Ddd2, D);
    return A;
}

/* The foot's response (contact.c's foot_response_m) differentiated along one direction, given the directional
 * derivatives of its ingredients: K11, K22, K12, the foot's arms g1 = (-al1 s1, al1 co1), g2 likewise, and 1 / m.
 * The fields Lxx, Lxy, Lyy, B1x, B1y, B2x, B2y of the result hold the derivatives (the others are not set). */
static inline leg_response response_direction(const leg_model *M, const leg_response *R, double s1, double co1, double s2,
                                              double co2, double dK11, double dK22, double dK12, double dg1x, double dg1y,
                                              double dg2x, double dg2y, double dinv_m)
{
    const double al1 = M->al1, al2 = M->al2;
    const double g1x = -al1 * s1, g1y = al1 * co1, g2x = -al2 * s2, g2y = al2 * co2;
    const double nB1x = R->B1x / R->inv_det, nB2x = R->B2x / R->inv_det, nB1y = R->B1y / R->inv_det, nB2y = R->B2y / R->inv_det;
    const double dinv = -(dK11 * R->K22 + R->K11 * dK22 - 2.0 * R->K12 * dK12) * R->inv_det * R->inv_det;
    leg_response D;
    D.B1x = (dK22 * g1x + R->K22 * dg1x - dK12 * g2x - R->K12 * dg2x) * R->inv_det + nB1x * dinv;
    D.B2x = (dK11 * g2x + R->K11 * dg2x - dK12 * g1x - R->K12 * dg1x) * R->inv_det + nB2x * dinv;
    D.B1y = (dK22 * g1y + R->K22 * dg1y - dK12 * g2y - R->K12 * dg2y) * R->inv_det + nB1y * dinv;
    D.B2y = (dK11 * g2y + R->K11 * dg2y - dK12 * g1y - R->K12 * dg1y) * R->inv_det + nB2y * dinv;
    D.Lxx = dinv_m + dg1x * R->B1x + g1x * D.B1x + dg2x * R->B2x + g2x * D.B2x;
    D.Lxy = dg1x * R->B1y + g1x * D.B1y + dg2x * R->B2y + g2x * D.B2y;
    D.Lyy = dinv_m + dg1y * R->B1y + g1y * D.B1y + dg2y * R->B2y + g2y * D.B2y;
    return D;
}

/* The foot's response differentiated along entry j of z (th1, th2 or a parameter; zero for the rates, the torques
 * and mu). */
static inline leg_response response_partial(const leg_model *M, const leg_response *R, double s1, double co1, double s2,
                                            double co2, const leg_model_d *dM, int j)
{
    const double s12 = s1 * co2 - co1 * s2, c12 = co1 * co2 + s1 * s2;
    if (j == 0)
        return response_direction(M, R, s1, co1, s2, co2, 0.0, 0.0, -M->kf * s12, -M->al1 * co1, -M->al1 * s1, 0.0, 0.0, 0.0);
    if (j == 1)
        return response_direction(M, R, s1, co1, s2, co2, 0.0, 0.0, M->kf * s12, 0.0, 0.0, -M->al2 * co2, -M->al2 * s2, 0.0);
    if (j >= LEG_NZ0) {
        const leg_model_d *d = &dM[j - LEG_NZ0];
        return response_direction(M, R, s1, co1, s2, co2, d->K11f, d->K22f, d->kf * c12, -d->al1 * s1, d->al1 * co1,
                                  -d->al2 * s2, d->al2 * co2, d->inv_m);
    }
    leg_response zero;
    memset(&zero, 0, sizeof zero);
    return zero;
}

/* slip_m's accelerations and their partials over the first nz entries of z: the free leg accelerations u = K^-1 r
 * are flight's (the same solve), the free foot acceleration a0 follows from them, lam_y = -a0_y / k with
 * k = Lyy - sigma mu Lxy, lam_x = -sigma mu lam_y, and the leg's accelerations are u + B lam (forced_accel). */
LEG_INLINE leg_accel slip_partials(int nz, const leg_model *M, double s1, double co1, double s2, double co2, double w1,
                                      double w2, double tau_hip, double tau_knee, double F, double mu, double sigma,
                                      leg_partials *D)
{
    const leg_accel A = slip_m(M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F, mu, sigma);
    const double m = M->m, a = M->a, b = M->b, al1 = M->al1, al2 = M->al2, v1 = w1 * w1, v2 = w2 * w2;
    const leg_response R = foot_response_m(M, s1, co1, s2, co2);
    const leg_free u = free_terms_m(M, &R, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
    leg_model_d dM[LEG_NPD];
    for (int k = 0; LEG_NZ0 + k < nz; k++)
        dM[k] = model_tangent(M, k);
    double R1[LEG_NZ], R2[LEG_NZ], dK11[LEG_NZ], dK22[LEG_NZ], dkf[LEG_NZ];
    flight_rhs(nz, M, s1, co1, s2, co2, w1, w2, F, dM, R1, R2, dK11, dK22, dkf);
    double Du1[LEG_NZ], Du2[LEG_NZ], scratch[4][LEG_NZ];
    link_partials(nz, M->K11f, M->K22f, M->kf, s1, co1, s2, co2, w1, w2, u.u1, u.u2, R1, R2, dK11, dK22, dkf, Du1, Du2,
                  scratch[0], scratch[1], scratch[2], scratch[3]);
    const double k = R.Lyy - sigma * mu * R.Lxy;
    const double lam_x = A.lam_x, lam_y = A.lam_y;
    const double dd1 = A.q1dd + A.thbdd, dd2 = A.q2dd + dd1;
    const double vx = co1 * v1 + s1 * dd1, vy = s1 * v1 - co1 * dd1, ux = co2 * v2 + s2 * dd2, uy = s2 * v2 - co2 * dd2;
    double Ddd1[LEG_NZ], Ddd2[LEG_NZ];
    for (int j = 0; j < nz; j++) {
        const leg_model_d *d = j >= LEG_NZ0 ? &dM[j - LEG_NZ0] : NULL;
        /* a0_y = al1 (co1 u1 - s1 w1^2) + al2 (co2 u2 - s2 w2^2) - g */
        double da0y = al1 * co1 * Du1[j] + al2 * co2 * Du2[j];
        if (j == 0)
            da0y += al1 * (-s1 * u.u1 - co1 * v1);
        else if (j == 1)
            da0y += al2 * (-s2 * u.u2 - co2 * v2);
        else if (j == 2)
            da0y += -2.0 * al1 * s1 * w1;
        else if (j == 3)
            da0y += -2.0 * al2 * s2 * w2;
        else if (d)
            da0y += d->al1 * (co1 * u.u1 - s1 * v1) + d->al2 * (co2 * u.u2 - s2 * v2) - d->g;
        const leg_response dR = response_partial(M, &R, s1, co1, s2, co2, dM, j);
        const double dmu = d ? d->mu : 0.0;
        const double dk = dR.Lyy - sigma * dmu * R.Lxy - sigma * mu * dR.Lxy;
        const double dly = (-da0y - lam_y * dk) / k, dlx = -sigma * (dmu * lam_y + mu * dly);
        Ddd1[j] = Du1[j] + R.B1x * dlx + R.B1y * dly + dR.B1x * lam_x + dR.B1y * lam_y;
        Ddd2[j] = Du2[j] + R.B2x * dlx + R.B2y * dly + dR.B2x * lam_x + dR.B2y * lam_y;
        /* vx = co1 w1^2 + s1 dd1, vy = s1 w1^2 - co1 dd1, ux, uy likewise (forced_accel) */
        double dvx = s1 * Ddd1[j], dvy = -co1 * Ddd1[j], dux = s2 * Ddd2[j], duy = -co2 * Ddd2[j];
        if (j == 0) {
            dvx += -s1 * v1 + co1 * dd1;
            dvy += co1 * v1 + s1 * dd1;
        } else if (j == 1) {
            dux += -s2 * v2 + co2 * dd2;
            duy += co2 * v2 + s2 * dd2;
        } else if (j == 2) {
            dvx += 2.0 * co1 * w1;
            dvy += 2.0 * s1 * w1;
        } else if (j == 3) {
            dux += 2.0 * co2 * w2;
            duy += 2.0 * s2 * w2;
        }
        /* xdd = (lam_x + a vx + b ux + F) / m, ydd = (lam_y + a vy + b uy) / m - g */
        D->d[0][j] = (dlx + a * dvx + b * dux) / m;
        D->d[1][j] = (dly + a * dvy + b * duy) / m;
        if (d) {
            D->d[0][j] += (d->a * vx + d->b * ux) / m - (lam_x + a * vx + b * ux + F) * d->m / (m * m);
            D->d[1][j] += (d->a * vy + d->b * uy) / m - (lam_y + a * vy + b * uy) * d->m / (m * m) - d->g;
        }
        D->d[5][j] = dlx;
        D->d[6][j] = dly;
    }
    joint_rows(nz, M, tau_hip, Ddd1, Ddd2, D);
    return A;
}

/* The partials of the mode `mode` over the first nz entries of z. */
LEG_INLINE leg_accel mode_partials(int nz, int mode, const leg_model *M, const leg_drive *u, double s1, double co1, double s2,
                                      double co2, double w1, double w2, leg_partials *D)
{
    if (mode == LEG_STICK)
        return stance_partials(nz, M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x, D);
    if (mode == LEG_FLIGHT)
        return flight_partials(nz, M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x, D);
    return slip_partials(nz, M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x, u->mu, slip_sigma(mode), D);
}

/* Column j's z: the leg's angles and rates from the state's tangent dS, the torques' tangent dtau, and a parameter
 * column's indicator. */
LEG_INLINE void z_of(int nz, const leg_tangent *dS, const double dtau[LEG_NU][LEG_NT], int j, double *dz)
{
    const double dth1 = dS->t[IA][j] + dS->t[IB][j];
    const double dw1 = dS->t[IVA][j] + dS->t[IVB][j];
    dz[0] = dth1;
    dz[1] = dth1 + dS->t[IC][j];
    dz[2] = dw1;
    dz[3] = dw1 + dS->t[IVC][j];
    dz[4] = dtau[0][j];
    dz[5] = dtau[1][j];
    for (int k = LEG_NZ0; k < nz; k++)
        dz[k] = 0.0;
    const int p = param_of(j);
    if (p >= 0 && LEG_NZ0 + p < nz)
        dz[LEG_NZ0 + p] = 1.0;
}

/* Whether row i of a tangent is the base's position or velocity: in stick the projection sets them after every
 * substep from the leg, and nothing in the substep reads them (base 0 skips them). */
static inline int base_row(int i) { return i == IX || i == IY || i == IVX || i == IVY; }

/* One RK4 stage's derivative k = (qd, qdd) and its tangent dk = (dS's rates, D dz), for the stage's state tangent dS. */
LEG_INLINE void stage_tangent(int nc, int nz, int base, const leg_partials *D, const leg_tangent *dS,
                                 const double dtau[LEG_NU][LEG_NT], leg_tangent *dk)
{
    for (int i = base ? 0 : IA; i < LEG_NQ; i++)
        for (int j = 0; j < nc; j++)
            dk->t[i][j] = dS->t[IVX + i][j];
    for (int j = 0; j < nc; j++) {
        double dz[LEG_NZ];
        z_of(nz, dS, dtau, j, dz);
        for (int r = base ? 0 : IA; r < LEG_NQ; r++) {
            double s = 0.0;
            for (int k = 0; k < nz; k++)
                s += D->d[r][k] * dz[k];
            dk->t[IVX + r][j] = s;
        }
    }
}

/* out = a + c b + f dh (column j: dh[j] times the primal derivative f; dh NULL: none), entry by entry. */
LEG_INLINE void tangent_axpy(int nc, int base, const leg_tangent *a, double c, const leg_tangent *b, const double *f,
                                const double *dh, double dh_scale, leg_tangent *out)
{
    for (int i = 0; i < LEG_NX; i++) {
        if (!base && base_row(i))
            continue;
        for (int j = 0; j < nc; j++)
            out->t[i][j] = a->t[i][j] + c * b->t[i][j];
        if (dh != NULL)
            for (int j = 0; j < nc; j++)
                out->t[i][j] += dh_scale * dh[j] * f[i];
    }
}

/* The lengths' derivatives of column j: d(l1), d(l2) (a parameter column's, else 0). */
static inline void lengths_of(int j, double *dl1, double *dl2)
{
    const int p = param_of(j);
    *dl1 = p == PL1 ? 1.0 : 0.0;
    *dl2 = p == PL2 ? 1.0 : 0.0;
}

/* The contact's projection (rk4_substep's) on the tangent of a substep's end state Y: in stick the base follows the
 * anchor and the leg, x_b = anchor_x - l1 co1 - l2 co2 and likewise y_b, (x_b, y_b)' = -(dp_f / d th) th'; in slip only
 * y_b and y_b'. danchor: the anchor's tangent (rows x, y). */
LEG_INLINE void project_tangent(int nc, int mode, const leg_params *P, const leg_x *Y, const double danchor[2][LEG_NT],
                                   leg_tangent *T)
{
    if (mode == LEG_FLIGHT)
        return;
    const double l1 = P->l1, l2 = P->l2, s1 = Y->s1, co1 = Y->c1, s2 = Y->s2, co2 = Y->c2;
    const double w1 = Y->va + Y->vb, w2 = w1 + Y->vc;
    for (int j = 0; j < nc; j++) {
        const double dth1 = T->t[IA][j] + T->t[IB][j], dth2 = dth1 + T->t[IC][j];
        const double dw1 = T->t[IVA][j] + T->t[IVB][j], dw2 = dw1 + T->t[IVC][j];
        double dl1, dl2;
        lengths_of(j, &dl1, &dl2);
        T->t[IY][j] = danchor[1][j] - l1 * co1 * dth1 - l2 * co2 * dth2 - dl1 * s1 - dl2 * s2;
        T->t[IVY][j] = l1 * (s1 * w1 * dth1 - co1 * dw1) + l2 * (s2 * w2 * dth2 - co2 * dw2) - dl1 * co1 * w1 - dl2 * co2 * w2;
        if (mode == LEG_STICK) {
            T->t[IX][j] = danchor[0][j] + l1 * s1 * dth1 + l2 * s2 * dth2 - dl1 * co1 - dl2 * co2;
            T->t[IVX][j] = l1 * (co1 * w1 * dth1 + s1 * dw1) + l2 * (co2 * w2 * dth2 + s2 * dw2) + dl1 * s1 * w1 + dl2 * s2 * w2;
        }
    }
}

/* The tangent of rk4_substep(mode, M, u, anchor, X, k1, h): T in, the end state's tangent out (in place), for the
 * first nc columns, of which the first nd are directions (nd: LEG_ND, or LEG_NDP with the parameters'). Y is the
 * substep's end state (rk4_substep's). dh (NULL: none): each column's derivative of the substep's length h. The
 * stages are rk4_substep's, at the same states. */
LEG_INLINE void substep_tangent_body(int nc, int nd, int mode, const leg_model *M, const leg_drive *u, const leg_x *X,
                                     double h, const leg_x *Y, const double dtau[LEG_NU][LEG_NT],
                                     const double danchor[2][LEG_NT], const double *dh, leg_tangent *T)
{
    const int base = mode != LEG_STICK; /* in stick the projection sets the base's rows from the leg's */
    const int nz = nd > LEG_ND ? LEG_NZ : LEG_NZ0;
    leg_partials D;
    leg_tangent dk1, dk2, dk3, dk4, dS;
    double S1, C1, S2, C2;
    /* stage 1 at X, then stages 2-4 at X + c k_prev with c = h/2, h/2, h: the stages of rk4_substep */
    static const double STAGE_C[3] = {RK4_HALF, RK4_HALF, 1.0};
    leg_tangent *const dk[4] = {&dk1, &dk2, &dk3, &dk4};
    double f[4][LEG_NX];
    double w1 = X->va + X->vb, w2 = w1 + X->vc;
    leg_accel k = mode_partials(nz, mode, M, u, X->s1, X->c1, X->s2, X->c2, w1, w2, &D);
    stage_tangent(nc, nz, base, &D, T, dtau, &dk1);
    const double f1[LEG_NX] = {X->vx, X->vy, X->va, X->vb, X->vc, k.xdd, k.ydd, k.thbdd, k.q1dd, k.q2dd};
    memcpy(f[0], f1, sizeof f1);
    for (int st = 1; st < 4; st++) {
        const double c = STAGE_C[st - 1] * h;
        const double vx = X->vx + c * k.xdd, vy = X->vy + c * k.ydd;
        const double va = X->va + c * k.thbdd, vb = X->vb + c * k.q1dd, vc = X->vc + c * k.q2dd;
        turn(X->s1, X->c1, c * w1, &S1, &C1);
        turn(X->s2, X->c2, c * w2, &S2, &C2);
        w1 = va + vb;
        w2 = w1 + vc;
        k = mode_partials(nz, mode, M, u, S1, C1, S2, C2, w1, w2, &D);
        tangent_axpy(nc, base, T, c, dk[st - 1], f[st - 1], dh, STAGE_C[st - 1], &dS);
        stage_tangent(nc, nz, base, &D, &dS, dtau, dk[st]);
        const double fs[LEG_NX] = {vx, vy, va, vb, vc, k.xdd, k.ydd, k.thbdd, k.q1dd, k.q2dd};
        memcpy(f[st], fs, sizeof fs);
    }
    /* y1 = y0 + h (k1 + 2 k2 + 2 k3 + k4) / 6 */
    for (int i = 0; i < LEG_NX; i++) {
        if (!base && base_row(i))
            continue;
        for (int j = 0; j < nc; j++)
            T->t[i][j] += h * (RK4_W0 * (dk1.t[i][j] + dk4.t[i][j]) + RK4_W1 * (dk2.t[i][j] + dk3.t[i][j]));
    }
    if (dh != NULL) {
        for (int i = 0; i < LEG_NX; i++) {
            if (!base && base_row(i))
                continue;
            const double fi = RK4_W0 * (f[0][i] + f[3][i]) + RK4_W1 * (f[1][i] + f[2][i]);
            for (int j = 0; j < nc; j++)
                T->t[i][j] += dh[j] * fi;
        }
    }
    project_tangent(nc, mode, &M->p, Y, danchor, T);
}

/* substep_tangent_body() with its column counts constants, so that the compiler unrolls the loops over z and
 * specialises each case. */
static void rk4_substep_tangent(int nc, int nd, int mode, const leg_model *M, const leg_drive *u, const leg_x *X, double h,
                                const leg_x *Y, const double dtau[LEG_NU][LEG_NT], const double danchor[2][LEG_NT],
                                const double *dh, leg_tangent *T)
{
    if (nd == LEG_ND) {
        if (nc == LEG_ND)
            substep_tangent_body(LEG_ND, LEG_ND, mode, M, u, X, h, Y, dtau, danchor, dh, T);
        else
            substep_tangent_body(LEG_ND + 1, LEG_ND, mode, M, u, X, h, Y, dtau, danchor, dh, T);
    } else {
        if (nc == LEG_NDP)
            substep_tangent_body(LEG_NDP, LEG_NDP, mode, M, u, X, h, Y, dtau, danchor, dh, T);
        else
            substep_tangent_body(LEG_NDP + 1, LEG_NDP, mode, M, u, X, h, Y, dtau, danchor, dh, T);
    }
}

/* The tangent's start: the identity on the state's and the torques' directions (and zero for the parameters'), and
 * the anchor's tangent where it follows the foot of the state at X (its x: follow >= 1; its y too: follow 2). */
static void tangent_start(const leg_params *P, const leg_x *X, int follow, leg_tangent *T, double dtau[LEG_NU][LEG_NT],
                          double danchor[2][LEG_NT])
{
    memset(T, 0, sizeof *T);
    memset(dtau, 0, sizeof(double) * LEG_NU * LEG_NT);
    memset(danchor, 0, sizeof(double) * 2 * LEG_NT);
    for (int i = 0; i < LEG_NX; i++)
        T->t[i][i] = 1.0;
    dtau[0][LEG_NX] = 1.0;
    dtau[1][LEG_NX + 1] = 1.0;
    if (follow) { /* p_f(q) = (x_b, y_b) + l1 (co1, s1) + l2 (co2, s2) */
        const double l1 = P->l1, l2 = P->l2, s1 = X->s1, co1 = X->c1, s2 = X->s2, co2 = X->c2;
        danchor[0][IX] = 1.0;
        danchor[0][IA] = danchor[0][IB] = -l1 * s1 - l2 * s2;
        danchor[0][IC] = -l2 * s2;
        danchor[0][LEG_ND + PL1] = co1;
        danchor[0][LEG_ND + PL2] = co2;
        if (follow == 2) {
            danchor[1][IY] = 1.0;
            danchor[1][IA] = danchor[1][IB] = l1 * co1 + l2 * co2;
            danchor[1][IC] = l2 * co2;
            danchor[1][LEG_ND + PL1] = s1;
            danchor[1][LEG_ND + PL2] = s2;
        }
    }
}

/* The Jacobians out of a tangent, row-major: A (10, 10), B (10, 2), and P (10, 12) if not NULL. */
static void tangent_out(const leg_tangent *T, double fill, double *A, double *B, double *Pj)
{
    for (int i = 0; i < LEG_NX; i++) {
        for (int j = 0; j < LEG_NX; j++)
            A[i * LEG_NX + j] = T->t[i][j] + fill;
        for (int j = 0; j < LEG_NU; j++)
            B[i * LEG_NU + j] = T->t[i][LEG_NX + j] + fill;
        if (Pj != NULL)
            for (int j = 0; j < LEG_NPD; j++)
                Pj[i * LEG_NPD + j] = T->t[i][LEG_ND + j] + fill;
    }
}

/* rk4_control_step() of one robot with its derivatives: A = d(q, qd) after / d(q, qd) before, B = d(q, qd) after /
 * d(tau_hip, tau_knee), and (Pj not NULL) Pj = d(q, qd) after / d(the parameters, mu) (mu's column zero: the pinned
 * foot has no friction). follow: the anchor is the foot of the state before the step (stance_step's default), so
 * that it moves with q; else it is held. Returns the RK4 steps taken. */
static int rk4_control_jacobians(const leg_params *P, const leg_drive *u, double *q, double *qd, const double *anchor,
                                 double dt, int substeps, double max_angle, int stance, int follow, double s1, double co1,
                                 double s2, double co2, double *lam_mean, double *A, double *B, double *Pj)
{
    const int n = substeps_for_rates(qd[2], qd[3], qd[4], dt, substeps, max_angle);
    const double h = dt / n;
    const int mode = stance ? LEG_STICK : LEG_FLIGHT, nd = Pj != NULL ? LEG_NDP : LEG_ND;
    leg_model M;
    model_init(&M, P);
    leg_x X = x_from(q, qd, s1, co1, s2, co2);
    leg_tangent T;
    double dtau[LEG_NU][LEG_NT], danchor[2][LEG_NT];
    tangent_start(P, &X, stance && follow ? 2 : 0, &T, dtau, danchor);
    leg_sums sums = {0.0, 0.0, 0.0};
    for (int i = 0; i < n; i++) {
        const leg_accel k1 = derivative(mode, &M, u, &X);
        const leg_x Y = rk4_substep(mode, &M, u, anchor, &X, &k1, h, &sums);
        rk4_substep_tangent(nd, nd, mode, &M, u, &X, h, &Y, dtau, danchor, NULL, &T);
        X = Y;
    }
    x_to(&X, q, qd);
    lam_mean[0] = sums.lx / n;
    lam_mean[1] = sums.ly / n;
    tangent_out(&T, 0.0, A, B, Pj);
    return n;
}

/* ---------------------------------------------------------------- the hybrid step's tangent (hybrid.c) */

/* Why the derivative of a hybrid step does not exist (a bit each; 0: it exists and is given). */
enum {
    LEG_D_GRAZING = 1,      /* a located event's witness crossed zero tangentially: its time has no derivative */
    LEG_D_SIMULTANEOUS = 2, /* two witnesses crossed at once: the order of the events is undefined */
    LEG_D_PAINLEVE = 4,     /* the Painleve rule chose the mode (no consistent contact force) */
    LEG_D_SETTLED = 8,      /* a Zeno settle held the foot on the ground */
};

/* What the derivative of a hybrid control step carries: the state's tangent, the torques' and the anchor's (rows x,
 * y; the ground's height is fixed), each column's derivative of the time the step has taken so far, and why the
 * derivative does not exist (LEG_D_* bits). The first nd columns are directions (LEG_ND, or LEG_NDP with the
 * parameters'); column nd is scratch: d/d(length) of a located substep. */
typedef struct {
    leg_tangent T;
    double dtau[LEG_NU][LEG_NT];
    double danchor[2][LEG_NT];
    double dtime[LEG_NT];
    int nd;
    int timed; /* an event has moved the time: later substeps' lengths depend on the directions */
    int undefined;
} leg_hybrid_tangent;

/* The foot's x, y and velocity differentiated along column j of T at X. */
static inline void foot_tangent(const leg_params *P, const leg_x *X, const leg_tangent *T, int j, double *dxf, double *dyf,
                                double *dvfx, double *dvfy)
{
    const double l1 = P->l1, l2 = P->l2, s1 = X->s1, co1 = X->c1, s2 = X->s2, co2 = X->c2;
    const double w1 = X->va + X->vb, w2 = w1 + X->vc;
    const double dth1 = T->t[IA][j] + T->t[IB][j], dth2 = dth1 + T->t[IC][j];
    const double dw1 = T->t[IVA][j] + T->t[IVB][j], dw2 = dw1 + T->t[IVC][j];
    double dl1, dl2;
    lengths_of(j, &dl1, &dl2);
    *dxf = T->t[IX][j] - l1 * s1 * dth1 - l2 * s2 * dth2 + dl1 * co1 + dl2 * co2;
    *dyf = T->t[IY][j] + l1 * co1 * dth1 + l2 * co2 * dth2 + dl1 * s1 + dl2 * s2;
    *dvfx = T->t[IVX][j] - l1 * (co1 * w1 * dth1 + s1 * dw1) - l2 * (co2 * w2 * dth2 + s2 * dw2) - dl1 * s1 * w1 - dl2 * s2 * w2;
    *dvfy = T->t[IVY][j] - l1 * (s1 * w1 * dth1 - co1 * dw1) - l2 * (s2 * w2 * dth2 - co2 * dw2) + dl1 * co1 * w1 + dl2 * co2 * w2;
}

/* The anchor set to the foot's x at X (a stick begins): its tangent follows the foot's. */
static inline void anchor_tangent(const leg_params *P, const leg_x *X, leg_hybrid_tangent *J)
{
    for (int j = 0; j < J->nd; j++) {
        double dxf, dyf, dvfx, dvfy;
        foot_tangent(P, X, &J->T, j, &dxf, &dyf, &dvfx, &dvfy);
        J->danchor[0][j] = dxf;
        J->danchor[1][j] = 0.0;
    }
}

/* The touchdown's placement: the base moved so that the foot is on the ground, y_b = ground - l1 s1 - l2 s2. */
static inline void placement_tangent(const leg_params *P, const leg_x *X, leg_hybrid_tangent *J)
{
    for (int j = 0; j < J->nd; j++) {
        const double dth1 = J->T.t[IA][j] + J->T.t[IB][j], dth2 = dth1 + J->T.t[IC][j];
        double dl1, dl2;
        lengths_of(j, &dl1, &dl2);
        J->T.t[IY][j] = -(P->l1 * X->c1 * dth1 + P->l2 * X->c2 * dth2 + dl1 * X->s1 + dl2 * X->s2);
    }
}

/* The tangent of a foot impulse applied at X (contact.c's impact_core for the foot velocity there, with friction mu;
 * mu = inf: the sticking impulse -Lambda^-1 v_f), then of the velocity jump M^-1 J^T P (impulse_velocity_m). Each
 * branch of impact_core is differentiated as it is taken: the sticking impulse from Lambda dP = -(dv_f + dLambda P);
 * Routh's sliding impulse along (-sigma mu, 1), and its sticking or reversed second phase, from their closed forms. */
static void impulse_tangent(const leg_model *M, const leg_x *X, double mu, leg_hybrid_tangent *J)
{
    const double m = M->m, a = M->a, b = M->b;
    const double s1 = X->s1, co1 = X->c1, s2 = X->s2, co2 = X->c2, w1 = X->va + X->vb, w2 = w1 + X->vc;
    const leg_response R = foot_response_m(M, s1, co1, s2, co2);
    double vfx, vfy, Px, Py;
    foot_velocity(&M->p, s1, co1, s2, co2, X->vx, X->vy, w1, w2, &vfx, &vfy);
    const leg_impact status = impact_core(vfx, vfy, mu, R.Lxx, R.Lxy, R.Lyy, &Px, &Py);
    if (status == LEG_IMPACT_NONE)
        return;
    if (status == LEG_IMPACT_PAINLEVE) {
        J->undefined |= LEG_D_PAINLEVE;
        return;
    }
    const double Lxx = R.Lxx, Lxy = R.Lxy, Lyy = R.Lyy, det = Lxx * Lyy - Lxy * Lxy;
    /* the branch impact_core took (its own tests, on the same numbers) */
    int branch = 0; /* 0 stick, 1 slide throughout, 2 slide then stick, 3 slide then slide back */
    double sigma = 0.0, sb = 0.0;
    if (!isinf(mu) && !(Py >= 0.0 && fabs(-(Lyy * vfx - Lxy * vfy) / det) <= mu * Py)) {
        const double P0x = -(Lyy * vfx - Lxy * vfy) / det;
        sigma = vfx > 0.0 ? 1.0 : (vfx < 0.0 ? -1.0 : (P0x < 0.0 ? 1.0 : -1.0));
        const double k = Lyy - sigma * mu * Lxy, r = Lxy - sigma * mu * Lxx, p_end = -vfy / k;
        if (sigma * (vfx + r * p_end) >= 0.0)
            branch = 1;
        else if (fabs(Lxy) <= mu * Lxx)
            branch = 2;
        else {
            branch = 3;
            sb = Lxy > 0.0 ? 1.0 : -1.0;
        }
    }
    const int nz = J->nd > LEG_ND ? LEG_NZ : LEG_NZ0;
    leg_model_d dM[LEG_NPD];
    for (int k = 0; LEG_NZ0 + k < nz; k++)
        dM[k] = model_tangent(M, k);
    leg_response DR[LEG_NZ];
    for (int i = 0; i < nz; i++)
        if (i < 2 || i >= LEG_NZ0)
            DR[i] = response_partial(M, &R, s1, co1, s2, co2, dM, i);
    const double jw1 = R.B1x * Px + R.B1y * Py, jw2 = R.B2x * Px + R.B2y * Py;
    for (int j = 0; j < J->nd; j++) {
        const double dth1 = J->T.t[IA][j] + J->T.t[IB][j], dth2 = dth1 + J->T.t[IC][j];
        double dxf, dyf, dvfx, dvfy;
        foot_tangent(&M->p, X, &J->T, j, &dxf, &dyf, &dvfx, &dvfy);
        /* the response's derivative along column j: through th1 and th2, and a parameter column's own */
        double dLxx = DR[0].Lxx * dth1 + DR[1].Lxx * dth2, dLxy = DR[0].Lxy * dth1 + DR[1].Lxy * dth2;
        double dLyy = DR[0].Lyy * dth1 + DR[1].Lyy * dth2;
        double dB1x = DR[0].B1x * dth1 + DR[1].B1x * dth2, dB1y = DR[0].B1y * dth1 + DR[1].B1y * dth2;
        double dB2x = DR[0].B2x * dth1 + DR[1].B2x * dth2, dB2y = DR[0].B2y * dth1 + DR[1].B2y * dth2;
        const int p = param_of(j);
        const leg_model_d *d = p >= 0 ? &dM[p] : NULL;
        if (d) {
            const leg_response *e = &DR[LEG_NZ0 + p];
            dLxx += e->Lxx;
            dLxy += e->Lxy;
            dLyy += e->Lyy;
            dB1x += e->B1x;
            dB1y += e->B1y;
            dB2x += e->B2x;
            dB2y += e->B2y;
        }
        const double dmu = d && !isinf(mu) ? d->mu : 0.0;
        double dPx, dPy;
        if (branch == 0) { /* Lambda dP = -(dv_f + dLambda P) */
            const double rx = -(dvfx + dLxx * Px + dLxy * Py), ry = -(dvfy + dLxy * Px + dLyy * Py);
            dPx = (Lyy * rx - Lxy * ry) / det;
            dPy = (Lxx * ry - Lxy * rx) / det;
        } else {
            const double k = Lyy - sigma * mu * Lxy, dk = dLyy - sigma * (dmu * Lxy + mu * dLxy);
            if (branch == 1) { /* P = p (-sigma mu, 1), p = -v_fy / k */
                const double pp = -vfy / k, dp = -(dvfy + pp * dk) / k;
                dPx = -sigma * (dmu * pp + mu * dp);
                dPy = dp;
            } else {
                const double r = Lxy - sigma * mu * Lxx, dr = dLxy - sigma * (dmu * Lxx + mu * dLxx);
                const double p1 = -vfx / r, dp1 = -(dvfx + p1 * dr) / r; /* sliding stops at p1 */
                const double vfy1 = vfy + k * p1, dvfy1 = dvfy + dk * p1 + k * dp1;
                if (branch == 2) { /* then sticks: p2 = -v_fy1 Lxx / det, Px = -sigma mu p1 - (Lxy / Lxx) p2 */
                    const double ddet = dLxx * Lyy + Lxx * dLyy - 2.0 * Lxy * dLxy;
                    const double p2 = -vfy1 * Lxx / det, dp2 = -(dvfy1 * Lxx + vfy1 * dLxx) / det - p2 * ddet / det;
                    const double ratio = Lxy / Lxx, dratio = (dLxy - ratio * dLxx) / Lxx;
                    dPx = -sigma * (dmu * p1 + mu * dp1) - dratio * p2 - ratio * dp2;
                    dPy = dp1 + dp2;
                } else { /* then slides back along (-sb mu, 1): p2 = -v_fy1 / k2 */
                    const double k2 = Lyy - sb * mu * Lxy, dk2 = dLyy - sb * (dmu * Lxy + mu * dLxy);
                    const double p2 = -vfy1 / k2, dp2 = -(dvfy1 + p2 * dk2) / k2;
                    dPx = -sigma * (dmu * p1 + mu * dp1) - sb * (dmu * p2 + mu * dp2);
                    dPy = dp1 + dp2;
                }
            }
        }
        /* the jump: w1 += B1x Px + B1y Py, w2 likewise; (x_b', y_b') += (P + a (s1, -co1) jw1 + b (s2, -co2) jw2) / m */
        const double djw1 = dB1x * Px + R.B1x * dPx + dB1y * Py + R.B1y * dPy;
        const double djw2 = dB2x * Px + R.B2x * dPx + dB2y * Py + R.B2y * dPy;
        double dvx = (dPx + a * (co1 * dth1 * jw1 + s1 * djw1) + b * (co2 * dth2 * jw2 + s2 * djw2)) / m;
        double dvy = (dPy - a * (-s1 * dth1 * jw1 + co1 * djw1) - b * (-s2 * dth2 * jw2 + co2 * djw2)) / m;
        if (d) {
            dvx += (d->a * s1 * jw1 + d->b * s2 * jw2) / m - (Px + a * s1 * jw1 + b * s2 * jw2) * d->m / (m * m);
            dvy += -(d->a * co1 * jw1 + d->b * co2 * jw2) / m - (Py - a * co1 * jw1 - b * co2 * jw2) * d->m / (m * m);
        }
        J->T.t[IVX][j] += dvx;
        J->T.t[IVY][j] += dvy;
        J->T.t[IVB][j] += djw1;
        J->T.t[IVC][j] += djw2 - djw1;
    }
}

/* The derivative of a located event's witness along column j of T at the located state X (mode `mode`, D its
 * partials there): TOUCHDOWN y_f, LIFTOFF lam_y, SLIP_ONSET mu lam_y - |lam_x|, SLIDING_STOP sigma x_f'. */
static inline double witness_tangent(int kind, int mode, int nz, const leg_params *P, const leg_x *X, const leg_accel *k,
                                     const leg_partials *D, const leg_tangent *T, const double dtau[LEG_NU][LEG_NT],
                                     double mu, int j)
{
    double dxf, dyf, dvfx, dvfy;
    foot_tangent(P, X, T, j, &dxf, &dyf, &dvfx, &dvfy);
    if (kind == LEG_TOUCHDOWN)
        return dyf;
    if (kind == LEG_SLIDING_STOP)
        return slip_sigma(mode) * dvfx;
    double dz[LEG_NZ], dlx = 0.0, dly = 0.0;
    z_of(nz, T, dtau, j, dz);
    for (int i = 0; i < nz; i++) {
        dlx += D->d[5][i] * dz[i];
        dly += D->d[6][i] * dz[i];
    }
    if (kind == LEG_LIFTOFF)
        return dly;
    const double dmu = nz > LEG_MU_DIR ? dz[LEG_MU_DIR] : 0.0;
    return dmu * k->lam_y + mu * dly - (k->lam_x > 0.0 ? 1.0 : -1.0) * dlx; /* SLIP_ONSET */
}

/* The tangent across a located event: the crossing substep from X (length s, ending at Xs) differentiated with s
 * fixed and along s (the scratch column), then s's derivative from the witness, ds = -dg / (dg/ds), folded in: the
 * saltation of the discrete map. The step's time moves by ds, so that later substeps' lengths follow. */
static void event_tangent(int kind, int mode, const leg_model *M, const leg_drive *u, const leg_x *X, double s,
                          const leg_x *Xs, leg_hybrid_tangent *J)
{
    const int nd = J->nd, sc = nd, nz = nd > LEG_ND ? LEG_NZ : LEG_NZ0;
    double dh[LEG_NT];
    for (int i = 0; i < LEG_NX; i++)
        J->T.t[i][sc] = 0.0;
    for (int j = 0; j < nd; j++)
        dh[j] = 0.0;
    dh[sc] = 1.0;
    J->dtau[0][sc] = J->dtau[1][sc] = J->danchor[0][sc] = J->danchor[1][sc] = 0.0;
    rk4_substep_tangent(nd + 1, nd, mode, M, u, X, s, Xs, J->dtau, J->danchor, dh, &J->T);
    leg_partials D;
    const leg_accel k = mode_partials(nz, mode, M, u, Xs->s1, Xs->c1, Xs->s2, Xs->c2, Xs->va + Xs->vb, Xs->va + Xs->vb + Xs->vc, &D);
    const double rate = witness_tangent(kind, mode, nz, &M->p, Xs, &k, &D, &J->T, J->dtau, u->mu, sc);
    double g[LEG_NDP], norm = 0.0;
    for (int j = 0; j < nd; j++) {
        g[j] = witness_tangent(kind, mode, nz, &M->p, Xs, &k, &D, &J->T, J->dtau, u->mu, j);
        norm = leg_fmax(norm, fabs(g[j]));
    }
    /* a crossing so slow that a relative change of 1e-12 of the state moves it by a whole control step: grazing */
    if (!(fabs(rate) > 1e-12 * norm) || rate == 0.0) {
        J->undefined |= LEG_D_GRAZING;
        return;
    }
    for (int j = 0; j < nd; j++) {
        const double ds = -g[j] / rate;
        for (int i = 0; i < LEG_NX; i++)
            J->T.t[i][j] += ds * J->T.t[i][sc];
        J->dtime[j] += ds;
    }
    J->timed = 1;
}
