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

#define LEG_NX 10                /* the state (q, qd) */
#define LEG_ND (LEG_NX + LEG_NU) /* tangent directions: the state's, then the torques' */
#define LEG_NT (LEG_ND + 1)      /* and one more column: d/d(length) of a substep whose length an event sets */
#define LEG_NZ 6                 /* what a mode's dynamics depend on: th1, th2, w1, w2, tau_hip, tau_knee */

enum { IX = 0, IY, IA, IB, IC, IVX, IVY, IVA, IVB, IVC }; /* rows of a tangent: leg_x's fields, in order */

/* d(xdd, ydd, thbdd, q1dd, q2dd, lam_x, lam_y) / dz at one state of one mode. */
typedef struct {
    double d[7][LEG_NZ];
} leg_partials;

/* d(state) / d(direction): one row per state entry, one column per direction (the first nc of LEG_NT in use). */
typedef struct {
    double t[LEG_NX][LEG_NT];
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

/* The foot's response (contact.c's foot_response_m) differentiated by th1 (D[0]) and th2 (D[1]): the fields Lxx,
 * Lxy, Lyy, B1x, B1y, B2x, B2y of D hold their derivatives (the others are not set). */
static inline void response_partials(const leg_model *M, const leg_response *R, double s1, double co1, double s2, double co2,
                                     leg_response D[2])
{
    const double kf = M->kf, al1 = M->al1, al2 = M->al2;
    const double s12 = s1 * co2 - co1 * s2;
    const double g1x = -al1 * s1, g1y = al1 * co1, g2x = -al2 * s2, g2y = al2 * co2;
    const double nB1x = R->B1x / R->inv_det, nB2x = R->B2x / R->inv_det, nB1y = R->B1y / R->inv_det, nB2y = R->B2y / R->inv_det;
    for (int k = 0; k < 2; k++) {
        const double dK12 = k == 0 ? -kf * s12 : kf * s12;
        const double dinv = 2.0 * R->K12 * dK12 * R->inv_det * R->inv_det; /* d (1 / (K11 K22 - K12^2)) */
        const double dg1x = k == 0 ? -al1 * co1 : 0.0, dg1y = k == 0 ? -al1 * s1 : 0.0;
        const double dg2x = k == 1 ? -al2 * co2 : 0.0, dg2y = k == 1 ? -al2 * s2 : 0.0;
        D[k].B1x = (R->K22 * dg1x - dK12 * g2x - R->K12 * dg2x) * R->inv_det + nB1x * dinv;
        D[k].B2x = (R->K11 * dg2x - dK12 * g1x - R->K12 * dg1x) * R->inv_det + nB2x * dinv;
        D[k].B1y = (R->K22 * dg1y - dK12 * g2y - R->K12 * dg2y) * R->inv_det + nB1y * dinv;
        D[k].B2y = (R->K11 * dg2y - dK12 * g1y - R->K12 * dg1y) * R->inv_det + nB2y * dinv;
        D[k].Lxx = dg1x * R->B1x + g1x * D[k].B1x + dg2x * R->B2x + g2x * D[k].B2x;
        D[k].Lxy = dg1x * R->B1y + g1x * D[k].B1y + dg2x * R->B2y + g2x * D[k].B2y;
        D[k].Lyy = dg1y * R->B1y + g1y * D[k].B1y + dg2y * R->B2y + g2y * D[k].B2y;
    }
}

/* slip_m's accelerations and their partials: the free leg accelerations u = K^-1 r are flight's (the same solve),
 * the free foot acceleration a0 follows from them, lam_y = -a0_y / k with k = Lyy - sigma mu Lxy, lam_x = -sigma mu
 * lam_y, and the leg's accelerations are u + B lam (contact.c's forced_accel). */
static inline leg_accel slip_partials(const leg_model *M, double s1, double co1, double s2, double co2, double w1, double w2,
                                      double tau_hip, double tau_knee, double F, double mu, double sigma, leg_partials *D)
{
    const leg_accel A = slip_m(M, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F, mu, sigma);
    const double m = M->m, a = M->a, b = M->b, kf = M->kf, al1 = M->al1, al2 = M->al2;
    const leg_response R = foot_response_m(M, s1, co1, s2, co2);
    const leg_free u = free_terms_m(M, &R, s1, co1, s2, co2, w1, w2, tau_hip, tau_knee, F);
    leg_response DR[2];
    response_partials(M, &R, s1, co1, s2, co2, DR);
    const double c12 = co1 * co2 + s1 * s2, s12 = s1 * co2 - co1 * s2, v1 = w1 * w1, v2 = w2 * w2;
    const double R1[LEG_NZ] = {-kf * c12 * v2 + F * a * co1 / m, kf * c12 * v2, 0.0, -2.0 * kf * s12 * w2, 1.0, -1.0};
    const double R2[LEG_NZ] = {kf * c12 * v1, -kf * c12 * v1 + F * b * co2 / m, 2.0 * kf * s12 * w1, 0.0, 0.0, 1.0};
    double Du1[LEG_NZ], Du2[LEG_NZ], scratch[4][LEG_NZ];
    link_partials(M->K11f, M->K22f, kf, s1, co1, s2, co2, w1, w2, u.u1, u.u2, R1, R2, Du1, Du2, scratch[0], scratch[1],
                  scratch[2], scratch[3]);
    const double k = R.Lyy - sigma * mu * R.Lxy;
    const double lam_x = A.lam_x, lam_y = A.lam_y;
    const double dd1 = A.q1dd + A.thbdd, dd2 = A.q2dd + dd1;
    for (int j = 0; j < LEG_NZ; j++) {
        /* a0_y = al1 (co1 u1 - s1 w1^2) + al2 (co2 u2 - s2 w2^2) - g */
        double da0y = al1 * co1 * Du1[j] + al2 * co2 * Du2[j];
        if (j == 0)
            da0y += al1 * (-s1 * u.u1 - co1 * v1);
        if (j == 1)
            da0y += al2 * (-s2 * u.u2 - co2 * v2);
        if (j == 2)
            da0y += -2.0 * al1 * s1 * w1;
        if (j == 3)
            da0y += -2.0 * al2 * s2 * w2;
        const leg_response *dR = j < 2 ? &DR[j] : NULL;
        const double dk = dR ? dR->Lyy - sigma * mu * dR->Lxy : 0.0;
        const double dly = (-da0y - lam_y * dk) / k, dlx = -sigma * mu * dly;
        double ddd1 = Du1[j] + R.B1x * dlx + R.B1y * dly, ddd2 = Du2[j] + R.B2x * dlx + R.B2y * dly;
        if (dR) {
            ddd1 += dR->B1x * lam_x + dR->B1y * lam_y;
            ddd2 += dR->B2x * lam_x + dR->B2y * lam_y;
        }
        /* vx = co1 w1^2 + s1 dd1, vy = s1 w1^2 - co1 dd1, ux, uy likewise (forced_accel) */
        double dvx = s1 * ddd1, dvy = -co1 * ddd1, dux = s2 * ddd2, duy = -co2 * ddd2;
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
        const double dthb = j == 4 ? -1.0 / M->p.I_b : 0.0;
        D->d[0][j] = (dlx + a * dvx + b * dux) / m;
        D->d[1][j] = (dly + a * dvy + b * duy) / m;
        D->d[2][j] = dthb;
        D->d[3][j] = ddd1 - dthb;
        D->d[4][j] = ddd2 - ddd1;
        D->d[5][j] = dlx;
        D->d[6][j] = dly;
    }
    return A;
}

/* The partials of the mode `mode`. */
static inline leg_accel mode_partials(int mode, const leg_model *M, const leg_drive *u, double s1, double co1, double s2,
                                      double co2, double w1, double w2, leg_partials *D)
{
    if (mode == LEG_STICK)
        return stance_partials(M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x, D);
    if (mode == LEG_FLIGHT)
        return flight_partials(M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x, D);
    return slip_partials(M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x, u->mu, slip_sigma(mode), D);
}

/* One RK4 stage's derivative k = (qd, qdd) and its tangent dk = (dS's rates, D dz), for the stage's state tangent dS.
 * dtau: the torques' tangent (rows tau_hip, tau_knee). */
static inline void stage_tangent(int nc, int base, const leg_partials *D, const leg_tangent *dS,
                                 const double dtau[LEG_NU][LEG_NT], leg_tangent *dk)
{
    for (int i = base ? 0 : IA; i < LEG_NQ; i++)
        for (int j = 0; j < nc; j++)
            dk->t[i][j] = dS->t[IVX + i][j];
    for (int j = 0; j < nc; j++) {
        const double dth1 = dS->t[IA][j] + dS->t[IB][j], dth2 = dth1 + dS->t[IC][j];
        const double dw1 = dS->t[IVA][j] + dS->t[IVB][j], dw2 = dw1 + dS->t[IVC][j];
        const double dz[LEG_NZ] = {dth1, dth2, dw1, dw2, dtau[0][j], dtau[1][j]};
        for (int r = base ? 0 : IA; r < LEG_NQ; r++) {
            double s = 0.0;
            for (int k = 0; k < LEG_NZ; k++)
                s += D->d[r][k] * dz[k];
            dk->t[IVX + r][j] = s;
        }
    }
}

/* Whether row i of a tangent is the base's position or velocity: in stick the projection sets them after every
 * substep from the leg, and nothing in the substep reads them (base 0 skips them). */
static inline int base_row(int i) { return i == IX || i == IY || i == IVX || i == IVY; }

/* out = a + c b + f dh (column j: dh[j] times the primal derivative f; dh NULL: none), entry by entry. */
static inline void tangent_axpy(int nc, int base, const leg_tangent *a, double c, const leg_tangent *b, const double *f,
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

/* The contact's projection (rk4_substep's) on the tangent of a substep's end state Y: in stick the base follows the
 * anchor and the leg, x_b = anchor_x - l1 co1 - l2 co2 and likewise y_b, (x_b, y_b)' = -(dp_f / d th) th'; in slip only
 * y_b and y_b'. danchor: the anchor's tangent (rows x, y). */
static inline void project_tangent(int nc, int mode, const leg_params *P, const leg_x *Y, const double danchor[2][LEG_NT],
                                   leg_tangent *T)
{
    if (mode == LEG_FLIGHT)
        return;
    const double l1 = P->l1, l2 = P->l2, s1 = Y->s1, co1 = Y->c1, s2 = Y->s2, co2 = Y->c2;
    const double w1 = Y->va + Y->vb, w2 = w1 + Y->vc;
    for (int j = 0; j < nc; j++) {
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

/* The tangent of rk4_substep(mode, M, u, anchor, X, k1, h): T in, the end state's tangent out (in place), for the
 * first nc columns. Y is the substep's end state (rk4_substep's). dh (NULL: none): each column's derivative of the
 * substep's length h. The stages are rk4_substep's, at the same states. */
static void rk4_substep_tangent(int nc, int mode, const leg_model *M, const leg_drive *u, const leg_x *X, double h,
                                const leg_x *Y, const double dtau[LEG_NU][LEG_NT], const double danchor[2][LEG_NT],
                                const double *dh, leg_tangent *T)
{
    const double ch = RK4_HALF * h;
    const int base = mode != LEG_STICK; /* in stick the projection sets the base's rows from the leg's */
    leg_partials D;
    leg_tangent dk1, dk2, dk3, dk4, dS;
    double S1, C1, S2, C2;
    /* stage 1 at X */
    const double w1 = X->va + X->vb, w2 = w1 + X->vc;
    const leg_accel k1 = mode_partials(mode, M, u, X->s1, X->c1, X->s2, X->c2, w1, w2, &D);
    stage_tangent(nc, base, &D, T, dtau, &dk1);
    const double f1[LEG_NX] = {X->vx, X->vy, X->va, X->vb, X->vc, k1.xdd, k1.ydd, k1.thbdd, k1.q1dd, k1.q2dd};
    /* stage 2 at X + h/2 k1 */
    const double vx2 = X->vx + ch * k1.xdd, vy2 = X->vy + ch * k1.ydd;
    const double va2 = X->va + ch * k1.thbdd, vb2 = X->vb + ch * k1.q1dd, vc2 = X->vc + ch * k1.q2dd;
    turn(X->s1, X->c1, ch * w1, &S1, &C1);
    turn(X->s2, X->c2, ch * w2, &S2, &C2);
    const double w1_2 = va2 + vb2, w2_2 = w1_2 + vc2;
    const leg_accel k2 = mode_partials(mode, M, u, S1, C1, S2, C2, w1_2, w2_2, &D);
    tangent_axpy(nc, base, T, ch, &dk1, f1, dh, RK4_HALF, &dS);
    stage_tangent(nc, base, &D, &dS, dtau, &dk2);
    const double f2[LEG_NX] = {vx2, vy2, va2, vb2, vc2, k2.xdd, k2.ydd, k2.thbdd, k2.q1dd, k2.q2dd};
    /* stage 3 at X + h/2 k2 */
    const double vx3 = X->vx + ch * k2.xdd, vy3 = X->vy + ch * k2.ydd;
    const double va3 = X->va + ch * k2.thbdd, vb3 = X->vb + ch * k2.q1dd, vc3 = X->vc + ch * k2.q2dd;
    turn(X->s1, X->c1, ch * w1_2, &S1, &C1);
    turn(X->s2, X->c2, ch * w2_2, &S2, &C2);
    const double w1_3 = va3 + vb3, w2_3 = w1_3 + vc3;
    const leg_accel k3 = mode_partials(mode, M, u, S1, C1, S2, C2, w1_3, w2_3, &D);
    tangent_axpy(nc, base, T, ch, &dk2, f2, dh, RK4_HALF, &dS);
    stage_tangent(nc, base, &D, &dS, dtau, &dk3);
    const double f3[LEG_NX] = {vx3, vy3, va3, vb3, vc3, k3.xdd, k3.ydd, k3.thbdd, k3.q1dd, k3.q2dd};
    /* stage 4 at X + h k3 */
    const double vx4 = X->vx + h * k3.xdd, vy4 = X->vy + h * k3.ydd;
    const double va4 = X->va + h * k3.thbdd, vb4 = X->vb + h * k3.q1dd, vc4 = X->vc + h * k3.q2dd;
    turn(X->s1, X->c1, h * w1_3, &S1, &C1);
    turn(X->s2, X->c2, h * w2_3, &S2, &C2);
    const leg_accel k4 = mode_partials(mode, M, u, S1, C1, S2, C2, va4 + vb4, va4 + vb4 + vc4, &D);
    tangent_axpy(nc, base, T, h, &dk3, f3, dh, 1.0, &dS);
    stage_tangent(nc, base, &D, &dS, dtau, &dk4);
    /* y1 = y0 + h (k1 + 2 k2 + 2 k3 + k4) / 6 */
    for (int i = 0; i < LEG_NX; i++) {
        if (!base && base_row(i))
            continue;
        for (int j = 0; j < nc; j++)
            T->t[i][j] += h * (RK4_W0 * (dk1.t[i][j] + dk4.t[i][j]) + RK4_W1 * (dk2.t[i][j] + dk3.t[i][j]));
    }
    if (dh != NULL) {
        const double f4[LEG_NX] = {vx4, vy4, va4, vb4, vc4, k4.xdd, k4.ydd, k4.thbdd, k4.q1dd, k4.q2dd};
        for (int i = 0; i < LEG_NX; i++) {
            if (!base && base_row(i))
                continue;
            const double f = RK4_W0 * (f1[i] + f4[i]) + RK4_W1 * (f2[i] + f3[i]);
            for (int j = 0; j < nc; j++)
                T->t[i][j] += dh[j] * f;
        }
    }
    project_tangent(nc, mode, &M->p, Y, danchor, T);
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
    double dtau[LEG_NU][LEG_NT] = {{0.0}}, danchor[2][LEG_NT] = {{0.0}};
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
        rk4_substep_tangent(LEG_ND, mode, &M, u, &X, h, &Y, dtau, danchor, NULL, &T);
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
 * derivative does not exist (LEG_D_* bits). Column LEG_ND is scratch: d/d(length) of a located substep. */
typedef struct {
    leg_tangent T;
    double dtau[LEG_NU][LEG_NT];
    double danchor[2][LEG_NT];
    double dtime[LEG_NT];
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
    *dxf = T->t[IX][j] - l1 * s1 * dth1 - l2 * s2 * dth2;
    *dyf = T->t[IY][j] + l1 * co1 * dth1 + l2 * co2 * dth2;
    *dvfx = T->t[IVX][j] - l1 * (co1 * w1 * dth1 + s1 * dw1) - l2 * (co2 * w2 * dth2 + s2 * dw2);
    *dvfy = T->t[IVY][j] - l1 * (s1 * w1 * dth1 - co1 * dw1) - l2 * (s2 * w2 * dth2 - co2 * dw2);
}

/* The anchor set to the foot's x at X (a stick begins): its tangent follows the foot's. */
static inline void anchor_tangent(const leg_params *P, const leg_x *X, leg_hybrid_tangent *J)
{
    for (int j = 0; j < LEG_ND; j++) {
        double dxf, dyf, dvfx, dvfy;
        foot_tangent(P, X, &J->T, j, &dxf, &dyf, &dvfx, &dvfy);
        J->danchor[0][j] = dxf;
        J->danchor[1][j] = 0.0;
    }
}

/* The tangent of a foot impulse applied at X (contact.c's impact_core for the foot velocity there, with friction mu;
 * mu = inf: the sticking impulse -Lambda^-1 v_f), then of the velocity jump M^-1 J^T P (impulse_velocity_m). Each
 * branch of impact_core is differentiated as it is taken: the sticking impulse from Lambda dP = -(dv_f + dLambda P);
 * Routh's sliding impulse along (-sigma mu, 1), and its sticking or reversed second phase, from their closed forms. */
static void impulse_tangent(const leg_model *M, const leg_x *X, double mu, leg_hybrid_tangent *J)
{
    const double m = M->m, a = M->a, b = M->b, l1 = M->p.l1, l2 = M->p.l2;
    const double s1 = X->s1, co1 = X->c1, s2 = X->s2, co2 = X->c2, w1 = X->va + X->vb, w2 = w1 + X->vc;
    const leg_response R = foot_response_m(M, s1, co1, s2, co2);
    leg_response DR[2];
    response_partials(M, &R, s1, co1, s2, co2, DR);
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
    for (int j = 0; j < LEG_ND; j++) {
        const double dth1 = J->T.t[IA][j] + J->T.t[IB][j], dth2 = dth1 + J->T.t[IC][j];
        double dxf, dyf, dvfx, dvfy;
        foot_tangent(&M->p, X, &J->T, j, &dxf, &dyf, &dvfx, &dvfy);
        const double dLxx = DR[0].Lxx * dth1 + DR[1].Lxx * dth2, dLxy = DR[0].Lxy * dth1 + DR[1].Lxy * dth2;
        const double dLyy = DR[0].Lyy * dth1 + DR[1].Lyy * dth2;
        double dPx, dPy;
        if (branch == 0) { /* Lambda dP = -(dv_f + dLambda P) */
            const double rx = -(dvfx + dLxx * Px + dLxy * Py), ry = -(dvfy + dLxy * Px + dLyy * Py);
            dPx = (Lyy * rx - Lxy * ry) / det;
            dPy = (Lxx * ry - Lxy * rx) / det;
        } else {
            const double k = Lyy - sigma * mu * Lxy, dk = dLyy - sigma * mu * dLxy;
            if (branch == 1) { /* P = p (-sigma mu, 1), p = -v_fy / k */
                const double p = -vfy / k, dp = -(dvfy + p * dk) / k;
                dPx = -sigma * mu * dp;
                dPy = dp;
            } else {
                const double r = Lxy - sigma * mu * Lxx, dr = dLxy - sigma * mu * dLxx;
                const double p1 = -vfx / r, dp1 = -(dvfx + p1 * dr) / r; /* sliding stops at p1 */
                const double vfy1 = vfy + k * p1, dvfy1 = dvfy + dk * p1 + k * dp1;
                if (branch == 2) { /* then sticks: p2 = -v_fy1 Lxx / det, Px = -sigma mu p1 - (Lxy / Lxx) p2 */
                    const double ddet = dLxx * Lyy + Lxx * dLyy - 2.0 * Lxy * dLxy;
                    const double p2 = -vfy1 * Lxx / det, dp2 = -(dvfy1 * Lxx + vfy1 * dLxx) / det - p2 * ddet / det;
                    const double ratio = Lxy / Lxx, dratio = (dLxy - ratio * dLxx) / Lxx;
                    dPx = -sigma * mu * dp1 - dratio * p2 - ratio * dp2;
                    dPy = dp1 + dp2;
                } else { /* then slides back along (-sb mu, 1): p2 = -v_fy1 / k2 */
                    const double k2 = Lyy - sb * mu * Lxy, dk2 = dLyy - sb * mu * dLxy;
                    const double p2 = -vfy1 / k2, dp2 = -(dvfy1 + p2 * dk2) / k2;
                    dPx = -sigma * mu * dp1 - sb * mu * dp2;
                    dPy = dp1 + dp2;
                }
            }
        }
        /* the jump: dw1 = B1x Px + B1y Py, dw2 likewise; (x_b', y_b') += (P + a (s1, -co1) dw1 + b (s2, -co2) dw2) / m */
        const double dB1x = DR[0].B1x * dth1 + DR[1].B1x * dth2, dB1y = DR[0].B1y * dth1 + DR[1].B1y * dth2;
        const double dB2x = DR[0].B2x * dth1 + DR[1].B2x * dth2, dB2y = DR[0].B2y * dth1 + DR[1].B2y * dth2;
        const double jw1 = R.B1x * Px + R.B1y * Py, jw2 = R.B2x * Px + R.B2y * Py;
        const double djw1 = dB1x * Px + R.B1x * dPx + dB1y * Py + R.B1y * dPy;
        const double djw2 = dB2x * Px + R.B2x * dPx + dB2y * Py + R.B2y * dPy;
        J->T.t[IVX][j] += (dPx + a * (co1 * dth1 * jw1 + s1 * djw1) + b * (co2 * dth2 * jw2 + s2 * djw2)) / m;
        J->T.t[IVY][j] += (dPy - a * (-s1 * dth1 * jw1 + co1 * djw1) - b * (-s2 * dth2 * jw2 + co2 * djw2)) / m;
        J->T.t[IVB][j] += djw1;
        J->T.t[IVC][j] += djw2 - djw1;
    }
    (void)l1;
    (void)l2;
}

/* The derivative of a located event's witness along column j of T at the located state X (mode `mode`, D its
 * partials there): TOUCHDOWN y_f, LIFTOFF lam_y, SLIP_ONSET mu lam_y - |lam_x|, SLIDING_STOP sigma x_f'. */
static inline double witness_tangent(int kind, int mode, const leg_params *P, const leg_x *X, const leg_accel *k,
                                     const leg_partials *D, const leg_tangent *T, const double dtau[LEG_NU][LEG_NT],
                                     double mu, int j)
{
    double dxf, dyf, dvfx, dvfy;
    foot_tangent(P, X, T, j, &dxf, &dyf, &dvfx, &dvfy);
    if (kind == LEG_TOUCHDOWN)
        return dyf;
    if (kind == LEG_SLIDING_STOP)
        return slip_sigma(mode) * dvfx;
    const double dth1 = T->t[IA][j] + T->t[IB][j], dth2 = dth1 + T->t[IC][j];
    const double dw1 = T->t[IVA][j] + T->t[IVB][j], dw2 = dw1 + T->t[IVC][j];
    const double dz[LEG_NZ] = {dth1, dth2, dw1, dw2, dtau[0][j], dtau[1][j]};
    double dlx = 0.0, dly = 0.0;
    for (int i = 0; i < LEG_NZ; i++) {
        dlx += D->d[5][i] * dz[i];
        dly += D->d[6][i] * dz[i];
    }
    if (kind == LEG_LIFTOFF)
        return dly;
    return mu * dly - (k->lam_x > 0.0 ? 1.0 : -1.0) * dlx; /* SLIP_ONSET */
}

/* The tangent across a located event: the crossing substep from X (length s, ending at Xs) differentiated with s
 * fixed and along s (the scratch column), then s's derivative from the witness, ds = -dg / (dg/ds), folded in: the
 * saltation of the discrete map. The step's time moves by ds, so that later substeps' lengths follow. */
static void event_tangent(int kind, int mode, const leg_model *M, const leg_drive *u, const leg_x *X, double s,
                          const leg_x *Xs, leg_hybrid_tangent *J)
{
    double dh[LEG_NT];
    for (int i = 0; i < LEG_NX; i++)
        J->T.t[i][LEG_ND] = 0.0;
    for (int j = 0; j < LEG_ND; j++)
        dh[j] = 0.0;
    dh[LEG_ND] = 1.0;
    J->dtau[0][LEG_ND] = J->dtau[1][LEG_ND] = J->danchor[0][LEG_ND] = J->danchor[1][LEG_ND] = 0.0;
    rk4_substep_tangent(LEG_NT, mode, M, u, X, s, Xs, J->dtau, J->danchor, dh, &J->T);
    leg_partials D;
    const leg_accel k = mode_partials(mode, M, u, Xs->s1, Xs->c1, Xs->s2, Xs->c2, Xs->va + Xs->vb, Xs->va + Xs->vb + Xs->vc, &D);
    const double rate = witness_tangent(kind, mode, &M->p, Xs, &k, &D, &J->T, J->dtau, u->mu, LEG_ND);
    double g[LEG_ND], norm = 0.0;
    for (int j = 0; j < LEG_ND; j++) {
        g[j] = witness_tangent(kind, mode, &M->p, Xs, &k, &D, &J->T, J->dtau, u->mu, j);
        norm = leg_fmax(norm, fabs(g[j]));
    }
    /* a crossing so slow that a relative change of 1e-12 of the state moves it by a whole control step: grazing */
    if (!(fabs(rate) * 1.0 > 1e-12 * norm) || rate == 0.0) {
        J->undefined |= LEG_D_GRAZING;
        return;
    }
    for (int j = 0; j < LEG_ND; j++) {
        const double ds = -g[j] / rate;
        for (int i = 0; i < LEG_NX; i++)
            J->T.t[i][j] += ds * J->T.t[i][LEG_ND];
        J->dtime[j] += ds;
    }
    J->timed = 1;
}
