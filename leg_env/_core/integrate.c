/* Time stepping: RK4 with exact contact projection (the lesson's section 5; leg_env.integrate says it
 * for users).
 *
 * A control step of length dt is n classical RK4 steps of h = dt / n, n = max(substeps,
 * ceil(dt w_max / max_angle)) with w_max the largest link or joint rate at the step's start. After
 * every RK4 step of a contact mode the base is projected back onto the contact (coordinate
 * partitioning: only the base moves), so that the foot drift stays at round-off.
 *
 * Part of the unity build of module.c.
 */
#include <math.h>

#include "robot.h"

#define LEG_TURN_MAX 0.1 /* the largest angle increment turn() takes by its series */

static const double RK4_HALF = 0.5;           /* stage offsets: h/2, h/2, h */
static const double RK4_W0 = 1.0 / 6.0;       /* weights 1/6, 2/6, 2/6, 1/6 */
static const double RK4_W1 = 2.0 / 6.0;

/* RK4 steps for a control step of length dt: at least `substeps`, and enough that no link turns, and no
 * joint moves, by more than max_angle per RK4 step at the rates (th_b', q1', q2') = (va, vb, vc). */
static inline int substeps_for_rates(double va, double vb, double vc, double dt, int substeps, double max_angle)
{
    const double w = leg_fmax(leg_fmax(leg_fmax(fabs(va), fabs(vb)), leg_fmax(fabs(vc), fabs(va + vb))), fabs(va + vb + vc));
    const double need = w * dt / max_angle;
    if (need > substeps) {
        if (need > LEG_MAX_SUBSTEPS) /* infinite or absurd rates: cap the work, the caller flags the state */
            return LEG_MAX_SUBSTEPS;
        return (int)ceil(need);
    }
    return substeps; /* also for NaN rates: the state is already lost, the caller flags it */
}

/* (sin(th + d), cos(th + d)) from s = sin th, c = cos th by angle addition. Within a control step the
 * links turn by little, so sin d and cos d - 1 come from short Taylor series (the first omitted terms,
 * d^11/11! and d^12/12!, are below 3e-19 for |d| <= 0.1); a larger or non-finite d calls sin and cos. */
LEG_INLINE void turn(double s, double c, double d, double *s_out, double *c_out)
{
    static const double S3 = -1.0 / 6.0, S5 = 1.0 / 120.0, S7 = -1.0 / 5040.0, S9 = 1.0 / 362880.0;
    static const double C2 = -0.5, C4 = 1.0 / 24.0, C6 = -1.0 / 720.0, C8 = 1.0 / 40320.0, C10 = -1.0 / 3628800.0;
    double sd, cm;
    if (fabs(d) <= LEG_TURN_MAX) {
        const double d2 = d * d, d4 = d2 * d2;
        sd = d + d * d2 * ((S3 + d2 * S5) + d4 * (S7 + d2 * S9));
        cm = d2 * ((C2 + d2 * C4) + d4 * ((C6 + d2 * C8) + d4 * C10));
    } else {
        sd = sin(d);
        cm = cos(d) - 1.0;
    }
    *s_out = s + (s * cm + c * sd);
    *c_out = c + (c * cm - s * sd);
}

static inline int is_slip(int mode) { return mode == LEG_SLIP_FORWARD || mode == LEG_SLIP_BACKWARD; }

static inline double slip_sigma(int mode) { return mode == LEG_SLIP_FORWARD ? 1.0 : -1.0; }

/* Accelerations and force of the contact mode `mode`. */
LEG_INLINE leg_accel accel(int mode, const leg_model *M, const leg_drive *u, double s1, double co1, double s2,
                              double co2, double w1, double w2)
{
    if (mode == LEG_STICK)
        return stance_m(M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x);
    if (mode == LEG_FLIGHT)
        return flight_m(M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x);
    return slip_m(M, s1, co1, s2, co2, w1, w2, u->tau_hip, u->tau_knee, u->load_x, u->mu, slip_sigma(mode));
}

/* accel() at the integrator state X. */
LEG_INLINE leg_accel derivative(int mode, const leg_model *M, const leg_drive *u, const leg_x *X)
{
    const double w1 = X->va + X->vb, w2 = X->va + X->vb + X->vc;
    return accel(mode, M, u, X->s1, X->c1, X->s2, X->c2, w1, w2);
}

/* Base position and velocity that put the foot on `anchor` with Jc qd = 0. */
static inline void project_core(const leg_params *P, double s1, double co1, double s2, double co2, double w1,
                                double w2, const double *anchor, double *x, double *y, double *vx, double *vy)
{
    *x = anchor[0] - P->l1 * co1 - P->l2 * co2;
    *y = anchor[1] - P->l1 * s1 - P->l2 * s2;
    *vx = P->l1 * s1 * w1 + P->l2 * s2 * w2;
    *vy = -(P->l1 * co1 * w1 + P->l2 * co2 * w2);
}

/* Move only the base so that the foot sits exactly on `anchor` with Jc qd = 0. */
static void project_one(const leg_params *P, double *q, double *qd, const double *anchor)
{
    double s1, co1, s2, co2;
    leg_trig(q, &s1, &co1, &s2, &co2);
    const double w1 = qd[2] + qd[3], w2 = w1 + qd[4];
    project_core(P, s1, co1, s2, co2, w1, w2, anchor, &q[0], &q[1], &qd[0], &qd[1]);
}

/* What one RK4 step adds up: the RK4-weighted stage force sum_k w_k lam_k (h times it is the contact
 * impulse of the step) and, in slip, the RK4-weighted dissipated power sum_k w_k (-lam_x x_f')_k. */
typedef struct {
    double lx, ly, power;
} leg_sums;

/* One classical RK4 step of length h in `mode` from X with the stage-1 derivative k1, then the mode's
 * projection (at `anchor` with Jc qd = 0 in stick; on the line y = anchor[1] with zero normal velocity
 * in slip; none in flight). Every stage turns the sines/cosines by its angle increment (turn()). */
LEG_INLINE leg_x rk4_substep(int mode, const leg_model *M, const leg_drive *u, const double *anchor,
                                const leg_x *X, const leg_accel *k1, double h, leg_sums *sums)
{
    const leg_params *P = &M->p;
    const double l1 = P->l1, l2 = P->l2;
    const double ch = RK4_HALF * h;
    const double W0 = RK4_W0, W1 = RK4_W1;
    const int slip = is_slip(mode);
    const double w1 = X->va + X->vb, w2 = X->va + X->vb + X->vc;
    double S1, C1, S2, C2;
    /* stage 2: y0 + h/2 k1 */
    const double vx2 = X->vx + ch * k1->xdd, vy2 = X->vy + ch * k1->ydd, va2 = X->va + ch * k1->thbdd,
                 vb2 = X->vb + ch * k1->q1dd, vc2 = X->vc + ch * k1->q2dd;
    turn(X->s1, X->c1, ch * w1, &S1, &C1);
    turn(X->s2, X->c2, ch * w2, &S2, &C2);
    const double w1_2 = va2 + vb2, w2_2 = va2 + vb2 + vc2;
    const leg_accel k2 = accel(mode, M, u, S1, C1, S2, C2, w1_2, w2_2);
    double power = 0.0;
    if (slip)
        power = W0 * -k1->lam_x * (X->vx - l1 * X->s1 * w1 - l2 * X->s2 * w2)
                + W1 * -k2.lam_x * (vx2 - l1 * S1 * w1_2 - l2 * S2 * w2_2);
    /* stage 3: y0 + h/2 k2 */
    const double vx3 = X->vx + ch * k2.xdd, vy3 = X->vy + ch * k2.ydd, va3 = X->va + ch * k2.thbdd,
                 vb3 = X->vb + ch * k2.q1dd, vc3 = X->vc + ch * k2.q2dd;
    turn(X->s1, X->c1, ch * w1_2, &S1, &C1);
    turn(X->s2, X->c2, ch * w2_2, &S2, &C2);
    const double w1_3 = va3 + vb3, w2_3 = va3 + vb3 + vc3;
    const leg_accel k3 = accel(mode, M, u, S1, C1, S2, C2, w1_3, w2_3);
    if (slip)
        power += W1 * -k3.lam_x * (vx3 - l1 * S1 * w1_3 - l2 * S2 * w2_3);
    /* stage 4: y0 + h k3 */
    const double vx4 = X->vx + h * k3.xdd, vy4 = X->vy + h * k3.ydd, va4 = X->va + h * k3.thbdd,
                 vb4 = X->vb + h * k3.q1dd, vc4 = X->vc + h * k3.q2dd;
    turn(X->s1, X->c1, h * w1_3, &S1, &C1);
    turn(X->s2, X->c2, h * w2_3, &S2, &C2);
    const leg_accel k4 = accel(mode, M, u, S1, C1, S2, C2, va4 + vb4, va4 + vb4 + vc4);
    if (slip)
        power += W0 * -k4.lam_x * (vx4 - l1 * S1 * (va4 + vb4) - l2 * S2 * (va4 + vb4 + vc4));
    /* y1 = y0 + h (k1 + 2 k2 + 2 k3 + k4) / 6 */
    const double da = h * (W0 * X->va + W1 * va2 + W1 * va3 + W0 * va4);
    const double db = h * (W0 * X->vb + W1 * vb2 + W1 * vb3 + W0 * vb4);
    const double dc = h * (W0 * X->vc + W1 * vc2 + W1 * vc3 + W0 * vc4);
    leg_x Y;
    Y.x = X->x + h * (W0 * X->vx + W1 * vx2 + W1 * vx3 + W0 * vx4);
    Y.y = X->y + h * (W0 * X->vy + W1 * vy2 + W1 * vy3 + W0 * vy4);
    Y.a = X->a + da;
    Y.b = X->b + db;
    Y.c = X->c + dc;
    Y.vx = X->vx + h * (W0 * k1->xdd + W1 * k2.xdd + W1 * k3.xdd + W0 * k4.xdd);
    Y.vy = X->vy + h * (W0 * k1->ydd + W1 * k2.ydd + W1 * k3.ydd + W0 * k4.ydd);
    Y.va = X->va + h * (W0 * k1->thbdd + W1 * k2.thbdd + W1 * k3.thbdd + W0 * k4.thbdd);
    Y.vb = X->vb + h * (W0 * k1->q1dd + W1 * k2.q1dd + W1 * k3.q1dd + W0 * k4.q1dd);
    Y.vc = X->vc + h * (W0 * k1->q2dd + W1 * k2.q2dd + W1 * k3.q2dd + W0 * k4.q2dd);
    sums->lx = sums->lx + W0 * k1->lam_x + W1 * k2.lam_x + W1 * k3.lam_x + W0 * k4.lam_x;
    sums->ly = sums->ly + W0 * k1->lam_y + W1 * k2.lam_y + W1 * k3.lam_y + W0 * k4.lam_y;
    sums->power += power;
    turn(X->s1, X->c1, da + db, &Y.s1, &Y.c1);
    turn(X->s2, X->c2, da + db + dc, &Y.s2, &Y.c2);
    if (mode == LEG_STICK) { /* the projection, on the trigonometry just computed */
        project_core(P, Y.s1, Y.c1, Y.s2, Y.c2, Y.va + Y.vb, Y.va + Y.vb + Y.vc, anchor, &Y.x, &Y.y, &Y.vx, &Y.vy);
    } else if (mode != LEG_FLIGHT) { /* slip: the foot on the ground line, its normal velocity zero */
        Y.y = anchor[1] - l1 * Y.s1 - l2 * Y.s2;
        Y.vy = -(l1 * Y.c1 * (Y.va + Y.vb) + l2 * Y.c2 * (Y.va + Y.vb + Y.vc));
    }
    return Y;
}

static inline leg_x x_from(const double *q, const double *qd, double s1, double co1, double s2, double co2)
{
    leg_x X = {q[0], q[1], q[2], q[3], q[4], qd[0], qd[1], qd[2], qd[3], qd[4], s1, co1, s2, co2};
    return X;
}

static inline void x_to(const leg_x *X, double *q, double *qd)
{
    q[0] = X->x;
    q[1] = X->y;
    q[2] = X->a;
    q[3] = X->b;
    q[4] = X->c;
    qd[0] = X->vx;
    qd[1] = X->vy;
    qd[2] = X->va;
    qd[3] = X->vb;
    qd[4] = X->vc;
}

/* One control step of RK4 on one robot in place, with the foot pinned at `anchor` (stance) or free
 * (flight), given the sines/cosines of q's link angles; lam_mean gets the mean contact force. Returns the RK4
 * steps taken. */
static int rk4_control_step(const leg_params *P, const leg_drive *u, double *q, double *qd, const double *anchor,
                             double dt, int substeps, double max_angle, int stance, double s1, double co1, double s2,
                             double co2, double *lam_mean)
{
    const int n = substeps_for_rates(qd[2], qd[3], qd[4], dt, substeps, max_angle);
    const double h = dt / n;
    leg_model M;
    model_init(&M, P);
    leg_x X = x_from(q, qd, s1, co1, s2, co2);
    leg_sums sums = {0.0, 0.0, 0.0};
    if (stance) { /* the mode a constant in each loop: its stages compile to that mode's dynamics alone */
        for (int i = 0; i < n; i++) {
            const leg_accel k1 = derivative(LEG_STICK, &M, u, &X);
            X = rk4_substep(LEG_STICK, &M, u, anchor, &X, &k1, h, &sums);
        }
    } else {
        for (int i = 0; i < n; i++) {
            const leg_accel k1 = derivative(LEG_FLIGHT, &M, u, &X);
            X = rk4_substep(LEG_FLIGHT, &M, u, anchor, &X, &k1, h, &sums);
        }
    }
    x_to(&X, q, qd);
    lam_mean[0] = sums.lx / n;
    lam_mean[1] = sums.ly / n;
    return n;
}
