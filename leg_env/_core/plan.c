/* The model-predictive controllers' plan (policies.ilqr): one robot's plan rolled out over H control steps on the
 * hybrid step with the hopper's law (hopper.c) in closed loop plus a correction of its action at every step, with the
 * closed loop's Jacobians; and the Gauss-Newton iLQR backward pass on the corrections, for any pilot.
 *
 * policies.ilqr.PilotILQR._rollout is the same rollout in numpy for any pilot (the push MPC's stepping controller,
 * and the tests' reference for this one); policies.mpc.HopMPC calls this one. Compiled so that a plan of one robot
 * does not pay numpy's cost per step: a plan is some 70 steps of ten microseconds or so each.
 *
 * Part of the unity build of module.c: include only from there, after hybrid.c and hopper.c.
 */
#include <math.h>
#include <string.h>

#include "robot.h"

#define PLAN_NX 10 /* the state (q, qd) */
#define PLAN_NU 2  /* the actions */

/* The hopper's per-robot state (policies.hopper.HopperController's): what a plan starts from and carries. */
typedef struct {
    double bias, apex, since_touchdown;
    int64_t phase;
    unsigned char was_flight;
} plan_pilot;

/* The settings of a rollout besides the robot and the law's gains. */
typedef struct {
    double dt, max_angle, mu, law_step, clip_smoothing;
    int substeps;
} plan_settings;

/* The backward pass's derivative of clip(z, -1, 1) (policies.ilqr.PilotILQR.clip_derivative): 1 inside the band w
 * from the bounds, 0 at them, a smoothstep between; w = 0: the clip's own 0 or 1. */
static inline double plan_clip_derivative(double z, double w)
{
    if (w == 0.0)
        return fabs(z) < 1.0 ? 1.0 : 0.0;
    const double s = hop_clip((1.0 - fabs(z)) / w, 0.0, 1.0);
    return s * s * (3.0 - 2.0 * s);
}

/* The hopper's action (its torques over the limits) at the model state x in the contact mode `mode`, advancing its
 * state h: the law reads the observation of the state (policies.ilqr.PilotILQR._observation: the base's height
 * above the ground, the angles and rates, the contact flag) and the command; its drift is the COM's, exact on the
 * model, from x_ref. */
static void plan_law(const leg_params *P, const double *G, const double *x, int mode, double command, double x_ref, plan_pilot *h,
                     double *a)
{
    const double o[HOPPER_INPUTS] = {x[2], x[3], x[4], x[5], x[6], x[7], x[8], x[9], x[1], mode != LEG_FLIGHT ? 1.0 : 0.0, command};
    double pos[2], vel[2], tau[2], vx_com;
    com_one(P, x, x + LEG_NQ, pos, vel);
    hopper_torque_one(P, G, o, pos[0] - x_ref, &h->bias, &h->apex, &h->phase, &h->was_flight, &h->since_touchdown, tau, &vx_com);
    a[0] = tau[0] / G[HG_LIM_HIP];
    a[1] = tau[1] / G[HG_LIM_KNEE];
}

/* The law's derivative by the state, dpi (2 x 10): centred differences of step eps, each from the state h had before
 * the law advanced it at x. */
static void plan_law_derivative(const leg_params *P, const double *G, const double *x, int mode, double command, double x_ref,
                                const plan_pilot *h, double eps, double dpi[PLAN_NU][PLAN_NX])
{
    for (int j = 0; j < PLAN_NX; j++) {
        double xp[PLAN_NX], xm[PLAN_NX], ap[PLAN_NU], am[PLAN_NU];
        memcpy(xp, x, sizeof xp);
        memcpy(xm, x, sizeof xm);
        xp[j] = x[j] + eps;
        xm[j] = x[j] + (-eps);
        plan_pilot hp = *h, hm = *h;
        plan_law(P, G, xp, mode, command, x_ref, &hp, ap);
        plan_law(P, G, xm, mode, command, x_ref, &hm, am);
        for (int i = 0; i < PLAN_NU; i++)
            dpi[i][j] = (ap[i] - am[i]) / (2.0 * eps);
    }
}

/* One robot's plan: from (q0, qd0) in mode0 and the hopper's state h, H steps of the action
 * a_t = clip(pi(x_t) + v_t, -1, 1), v_t = corrections[t] + k[t] + K[t] (x_t - nominal[t]) (k, K: none where NULL;
 * nominal NULL: 0). Writes the states X (H + 1, 10), modes (H + 1), actions U (H, 2), the corrections as applied
 * V (H, 2) and each step's time in flight (H); and each not NULL, the closed loop's Jacobians A (H, 10, 10) =
 * A_step + B_step diag(lim) D dpi/dx and B (H, 10, 2) = B_step diag(lim) D, the action's derivative by the state
 * Du (H, 2, 10) = D dpi/dx and the clip's derivative D (H, 2) (any not NULL: the step's Jacobians formed); a step
 * whose derivative does not exist contributes A_step = I, B_step = 0. */
static void hop_plan_one(const leg_params *P, const double *G, const plan_settings *S, int H, const double *q0, const double *qd0,
                         int mode, plan_pilot h, double command, double x_ref, const double *corrections, const double *k,
                         const double *K, const double *nominal, double *X, int64_t *modes, double *U, double *V,
                         double *flight_time, double *A, double *B, double *Du, double *D)
{
    const double lim[PLAN_NU] = {G[HG_LIM_HIP], G[HG_LIM_KNEE]};
    memcpy(X, q0, LEG_NQ * sizeof(double));
    memcpy(X + LEG_NQ, qd0, LEG_NQ * sizeof(double));
    modes[0] = mode;
    for (int t = 0; t < H; t++) {
        const double *x = X + (size_t)t * PLAN_NX;
        double v[PLAN_NU], pi[PLAN_NU], dpi[PLAN_NU][PLAN_NX];
        for (int i = 0; i < PLAN_NU; i++) {
            v[i] = corrections[PLAN_NU * t + i];
            if (k != NULL)
                v[i] = v[i] + k[PLAN_NU * t + i];
            if (K != NULL) {
                double feedback = 0.0;
                for (int j = 0; j < PLAN_NX; j++)
                    feedback += K[((size_t)t * PLAN_NU + i) * PLAN_NX + j] * (x[j] - (nominal != NULL ? nominal[(size_t)t * PLAN_NX + j] : 0.0));
                v[i] = v[i] + feedback;
            }
        }
        const plan_pilot before = h;
        plan_law(P, G, x, mode, command, x_ref, &h, pi);
        const int jacobians = A != NULL || B != NULL || Du != NULL || D != NULL;
        if (jacobians)
            plan_law_derivative(P, G, x, mode, command, x_ref, &before, S->law_step, dpi);
        double u[PLAN_NU];
        for (int i = 0; i < PLAN_NU; i++) {
            u[i] = hop_clip(pi[i] + v[i], -1.0, 1.0);
            V[PLAN_NU * t + i] = v[i];
            U[PLAN_NU * t + i] = u[i];
        }
        const leg_drive drive = {u[0] * lim[0], u[1] * lim[1], 0.0, S->mu};
        double q[LEG_NQ], qd[LEG_NQ], anchor[2], s1, co1, s2, co2;
        memcpy(q, x, sizeof q);
        memcpy(qd, x + LEG_NQ, sizeof qd);
        foot_one(P, q, anchor); /* the contact point under the foot, on the ground y = 0 */
        anchor[1] = 0.0;
        leg_trig(q, &s1, &co1, &s2, &co2);
        leg_tally rec;
        if (jacobians) {
            double As[PLAN_NX * PLAN_NX], Bs[PLAN_NX * PLAN_NU], Bt[PLAN_NX][PLAN_NU], Dt[PLAN_NU];
            int m = mode;
            const int undefined = hybrid_control_jacobians(P, &drive, q, qd, &m, anchor, S->dt, S->substeps, S->max_angle, s1, co1, s2,
                                                           co2, 1, &rec, NULL, As, Bs, NULL);
            mode = m;
            for (int i = 0; i < PLAN_NU; i++)
                Dt[i] = plan_clip_derivative(pi[i] + v[i], S->clip_smoothing);
            for (int r = 0; r < PLAN_NX; r++)
                for (int i = 0; i < PLAN_NU; i++)
                    Bt[r][i] = (undefined ? 0.0 : Bs[r * PLAN_NU + i] * lim[i]) * Dt[i];
            for (int r = 0; A != NULL && r < PLAN_NX; r++)
                for (int j = 0; j < PLAN_NX; j++) {
                    const double a0 = undefined ? (r == j ? 1.0 : 0.0) : As[r * PLAN_NX + j];
                    A[((size_t)t * PLAN_NX + r) * PLAN_NX + j] = a0 + (Bt[r][0] * dpi[0][j] + Bt[r][1] * dpi[1][j]);
                }
            for (int r = 0; B != NULL && r < PLAN_NX; r++)
                for (int i = 0; i < PLAN_NU; i++)
                    B[((size_t)t * PLAN_NX + r) * PLAN_NU + i] = Bt[r][i];
            for (int i = 0; i < PLAN_NU; i++) {
                if (D != NULL)
                    D[PLAN_NU * t + i] = Dt[i];
                for (int j = 0; Du != NULL && j < PLAN_NX; j++)
                    Du[((size_t)t * PLAN_NU + i) * PLAN_NX + j] = Dt[i] * dpi[i][j];
            }
        } else {
            mode = hybrid_control_step(P, &drive, q, qd, mode, anchor, S->dt, S->substeps, S->max_angle, s1, co1, s2, co2, &rec, NULL);
        }
        double *next = X + (size_t)(t + 1) * PLAN_NX;
        memcpy(next, q, sizeof q);
        memcpy(next + LEG_NQ, qd, sizeof qd);
        modes[t + 1] = mode;
        flight_time[t] = rec.flight_time;
    }
}

/* ------------------------------------------------------------------------- the backward pass */

/* The iLQR backward pass's settings: the action residuals' weights (policies.ilqr.PilotILQR.action_residuals), the
 * corrections' and the regularisation of Q_vv, the torque limits. */
typedef struct {
    double effort_weight, power_weight, smooth_weight, regularisation, lim[PLAN_NU];
} plan_weights;

/* Solves M x = b in place for the 2 x 2 M and the m columns of b (its rows b0 and b1): Gaussian elimination with
 * partial pivoting (the equations swapped where the second's pivot is the larger; the unknowns keep their rows). */
static void plan_solve2(const double M[PLAN_NU][PLAN_NU], double *b0, double *b1, int m)
{
    const int swap = fabs(M[1][0]) > fabs(M[0][0]);
    const double a00 = M[swap][0], a01 = M[swap][1], a10 = M[!swap][0], a11 = M[!swap][1];
    const double l = a10 / a00, u11 = a11 - l * a01;
    for (int c = 0; c < m; c++) {
        const double r0 = swap ? b1[c] : b0[c], r1 = swap ? b0[c] : b1[c];
        const double x1 = (r1 - l * r0) / u11;
        b0[c] = (r0 - a01 * x1) / a00;
        b1[c] = x1;
    }
}

/* One robot's Gauss-Newton backward pass (policies.ilqr.PilotILQR._backward) over H steps: the gains k (H, 2) and
 * K (H, 2, 10) of the corrections, from half the state cost's gradient lx (H, 10) and its Gauss-Newton Hessian
 * lxx (H, 10, 10) at the state after each step, the closed loop's A (H, 10, 10), B (H, 10, 2), Du (H, 2, 10), the
 * clip's derivative D (H, 2), the states X (H + 1, 10), actions U (H, 2) and corrections V (H, 2). */
static void ilqr_backward_one(const plan_weights *W, int H, const double *lx, const double *lxx, const double *A, const double *B,
                              const double *D, const double *Du, const double *X, const double *U, const double *V, double *k,
                              double *K)
{
    enum { NX = PLAN_NX, NU = PLAN_NU, NR = 4 };
    const double se = sqrt(W->effort_weight), sp = sqrt(W->power_weight), ws = W->smooth_weight;
    double Vx[NX] = {0.0}, Vxx[NX][NX];
    memset(Vxx, 0, sizeof Vxx);
    for (int t = H - 1; t >= 0; t--) {
        const double *At = A + (size_t)t * NX * NX, *Bt = B + (size_t)t * NX * NU, *Dt = D + (size_t)t * NU;
        const double *Dut = Du + (size_t)t * NU * NX, *x = X + (size_t)t * NX, *u = U + (size_t)t * NU;
        double vx[NX], vxx[NX][NX];
        for (int i = 0; i < NX; i++) {
            vx[i] = lx[(size_t)t * NX + i] + Vx[i];
            for (int j = 0; j < NX; j++)
                vxx[i][j] = lxx[((size_t)t * NX + i) * NX + j] + Vxx[i][j];
        }
        /* the action's residuals: the effort, the joints' positive power; their derivatives by u and by x */
        double ra[NR], Jau[NR][NU] = {{0.0}}, Jax[NR][NX] = {{0.0}};
        for (int i = 0; i < NU; i++) {
            const double w = x[8 + i], power = W->lim[i] * u[i] * w, on = power > 0.0 ? 1.0 : 0.0;
            ra[i] = se * u[i];
            ra[2 + i] = sp * on * power;
            Jau[i][i] = se;
            Jau[2 + i][i] = sp * on * W->lim[i] * w;
            Jax[2 + i][8 + i] = sp * on * W->lim[i] * u[i];
        }
        /* through u = clip(pi(x) + v): du/dv = D, du/dx = D dpi/dx */
        double Jv[NR][NU], Jx[NR][NX];
        for (int r = 0; r < NR; r++) {
            for (int i = 0; i < NU; i++)
                Jv[r][i] = Jau[r][i] * Dt[i];
            for (int j = 0; j < NX; j++)
                Jx[r][j] = Jau[r][0] * Dut[j] + Jau[r][1] * Dut[NX + j] + Jax[r][j];
        }
        double Qx[NX], Qu[NU], VA[NX][NX], VB[NX][NU], Qxx[NX][NX], Quu[NU][NU], Qux[NU][NX];
        for (int j = 0; j < NX; j++) {
            double s = 0.0;
            for (int i = 0; i < NX; i++)
                s += At[i * NX + j] * vx[i];
            for (int r = 0; r < NR; r++)
                s += Jx[r][j] * ra[r];
            Qx[j] = s;
        }
        for (int c = 0; c < NU; c++) {
            double s = 0.0;
            for (int i = 0; i < NX; i++)
                s += Bt[i * NU + c] * vx[i];
            for (int r = 0; r < NR; r++)
                s += Jv[r][c] * ra[r];
            Qu[c] = s + ws * V[(size_t)t * NU + c];
        }
        for (int i = 0; i < NX; i++) {
            for (int j = 0; j < NX; j++) {
                double s = 0.0;
                for (int l = 0; l < NX; l++)
                    s += vxx[i][l] * At[l * NX + j];
                VA[i][j] = s;
            }
            for (int c = 0; c < NU; c++) {
                double s = 0.0;
                for (int l = 0; l < NX; l++)
                    s += vxx[i][l] * Bt[l * NU + c];
                VB[i][c] = s;
            }
        }
        for (int i = 0; i < NX; i++)
            for (int j = 0; j < NX; j++) {
                double s = 0.0;
                for (int l = 0; l < NX; l++)
                    s += At[l * NX + i] * VA[l][j];
                for (int r = 0; r < NR; r++)
                    s += Jx[r][i] * Jx[r][j];
                Qxx[i][j] = s;
            }
        for (int a = 0; a < NU; a++) {
            for (int c = 0; c < NU; c++) {
                double s = 0.0;
                for (int l = 0; l < NX; l++)
                    s += Bt[l * NU + a] * VB[l][c];
                for (int r = 0; r < NR; r++)
                    s += Jv[r][a] * Jv[r][c];
                Quu[a][c] = s + (a == c ? ws + W->regularisation : 0.0);
            }
            for (int j = 0; j < NX; j++) {
                double s = 0.0;
                for (int l = 0; l < NX; l++)
                    s += VB[l][a] * At[l * NX + j];
                for (int r = 0; r < NR; r++)
                    s += Jv[r][a] * Jx[r][j];
                Qux[a][j] = s;
            }
        }
        /* k = -Quu^-1 Qu, K = -Quu^-1 Qux, solved together */
        double rhs[NU][NX + 1];
        for (int a = 0; a < NU; a++) {
            rhs[a][0] = -Qu[a];
            for (int j = 0; j < NX; j++)
                rhs[a][1 + j] = -Qux[a][j];
        }
        plan_solve2(Quu, rhs[0], rhs[1], NX + 1);
        double kt[NU], Kt[NU][NX];
        for (int a = 0; a < NU; a++) {
            kt[a] = rhs[a][0];
            k[(size_t)t * NU + a] = kt[a];
            for (int j = 0; j < NX; j++)
                Kt[a][j] = K[((size_t)t * NU + a) * NX + j] = rhs[a][1 + j];
        }
        /* the value's expansion at the step's start */
        double g[NU];
        for (int a = 0; a < NU; a++)
            g[a] = Quu[a][0] * kt[0] + Quu[a][1] * kt[1] + Qu[a];
        for (int j = 0; j < NX; j++)
            Vx[j] = Qx[j] + (Kt[0][j] * g[0] + Kt[1][j] * g[1]) + (Qux[0][j] * kt[0] + Qux[1][j] * kt[1]);
        double QK[NU][NX]; /* Quu K */
        for (int a = 0; a < NU; a++)
            for (int j = 0; j < NX; j++)
                QK[a][j] = Quu[a][0] * Kt[0][j] + Quu[a][1] * Kt[1][j];
        for (int i = 0; i < NX; i++)
            for (int j = 0; j < NX; j++)
                Vxx[i][j] = Qxx[i][j] + (Kt[0][i] * QK[0][j] + Kt[1][i] * QK[1][j]) + (Kt[0][i] * Qux[0][j] + Kt[1][i] * Qux[1][j])
                            + (Qux[0][i] * Kt[0][j] + Qux[1][i] * Kt[1][j]);
        for (int i = 0; i < NX; i++)
            for (int j = 0; j < i; j++)
                Vxx[i][j] = Vxx[j][i] = 0.5 * (Vxx[i][j] + Vxx[j][i]);
    }
}
