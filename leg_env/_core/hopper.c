/* The hopping controller's law (policies.hopper, Raibert's three servos on the articulated leg): one robot's joint
 * torques from its observed state, advancing its stance phase and apex bias. policies.hopper.HopperController is its
 * Python face (the gains, the per-robot state, the documentation of the law); the model-predictive controllers call
 * it inside their plans. Compiled so that a plan of one robot does not pay numpy's cost per call.
 *
 * Part of the unity build of module.c: include only from there, after dynamics.c.
 */
#include <math.h>

#include "robot.h"

/* The law's settings, a float64 row (policies.hopper.HopperController._gains writes it in this order). */
enum {
    HG_L_TD,        /* the leg length held in flight [m] */
    HG_Q2_LO,       /* the knee angle that ends the push [rad] */
    HG_L_LO,        /* the virtual leg's length at that knee angle [m] */
    HG_ALPHA_LO,    /* the virtual leg's angle from the thigh there [rad] */
    HG_CROUCH0,     /* the crouch depth L_lo - L_low = c_0 + c_1 dh* */
    HG_CROUCH1,
    HG_V_SINK,      /* [m/s] */
    HG_A_C,         /* [m/s^2] */
    HG_K_C,         /* [1/s] */
    HG_STROKE_MIN,  /* [m] */
    HG_APEX_GAIN,   /* per hop */
    HG_T_S,         /* [s] */
    HG_K_V,         /* [s] */
    HG_K_X,         /* [1/s] */
    HG_K_H,         /* [1/s] */
    HG_K_TH,        /* [1/s^2] */
    HG_FRICTION,    /* the share of the friction cone lam_x may use */
    HG_K_P,         /* [1/s^2] */
    HG_K_D,         /* [1/s] */
    HG_Y_STAND,     /* the nominal posture's COM height [m] */
    HG_MU,          /* the friction coefficient */
    HG_DT,          /* the control period [s] */
    HG_LIM_HIP,     /* the joints' torque limits [N m] */
    HG_LIM_KNEE,
    HG_KNEE_TD,     /* the knee angle of a leg of length L_td [rad] */
    HG_ALPHA_TD,    /* the virtual leg's angle from the thigh there [rad] */
    HG_DWELL,       /* the shortest time from touchdown to the push [s] */
    HG_DWELL_KP,    /* the COM's servo over the foot while it waits there [1/s^2, 1/s] */
    HG_DWELL_KD,
    HOPPER_GAINS
};

enum { HOP_CROUCH = 0, HOP_PUSH = 1, HOP_RELEASE = 2 }; /* the stance phases */

/* The law's reading of the observation, a float64 row (policies.hopper.LAW_COLUMNS in this order). */
enum { HO_TH_B, HO_Q1, HO_Q2, HO_VX_B, HO_VY_B, HO_W_B, HO_W_Q1, HO_W_Q2, HO_BASE_Y, HO_CONTACT, HO_COMMAND, HOPPER_INPUTS };

static inline double hop_max(double x, double y) { return x >= y ? x : y; }
static inline double hop_min(double x, double y) { return x <= y ? x : y; }
static inline double hop_clip(double x, double lo, double hi) { return hop_min(hop_max(x, lo), hi); }

/* (angle + pi) mod 2 pi - pi, the modulo of the divisor's sign (Python's and numpy's) */
static inline double hop_wrap(double angle)
{
    const double period = 2.0 * M_PI;
    double r = fmod(angle + M_PI, period);
    if (r < 0.0)
        r += period;
    return r - M_PI;
}

/* The whole-body angular momentum about the COM [kg m^2/s], from positions and velocities relative to the hip. */
static double hop_angular_momentum(const leg_params *P, double m, double wb, double w1, double w2, double s1, double c1,
                                   double s2, double c2)
{
    const double t_x = P->c1 * c1, t_y = P->c1 * s1, t_vx = -P->c1 * s1 * w1, t_vy = P->c1 * c1 * w1; /* thigh's COM */
    const double s_x = P->l1 * c1 + P->c2 * c2, s_y = P->l1 * s1 + P->c2 * s2;                       /* shank's COM */
    const double s_vx = -P->l1 * s1 * w1 - P->c2 * s2 * w2, s_vy = P->l1 * c1 * w1 + P->c2 * c2 * w2;
    const double g_x = (P->m1 * t_x + P->m2 * s_x) / m, g_y = (P->m1 * t_y + P->m2 * s_y) / m;
    const double g_vx = (P->m1 * t_vx + P->m2 * s_vx) / m, g_vy = (P->m1 * t_vy + P->m2 * s_vy) / m;
    double H = P->I_b * wb + P->I1 * w1 + P->I2 * w2;
    H = H + P->m_b * ((0.0 - g_x) * (0.0 - g_vy) - (0.0 - g_y) * (0.0 - g_vx));
    H = H + P->m1 * ((t_x - g_x) * (t_vy - g_vy) - (t_y - g_y) * (t_vx - g_vx));
    H = H + P->m2 * ((s_x - g_x) * (s_vy - g_vy) - (s_y - g_y) * (s_vx - g_vx));
    return H;
}

/* The torques under which the stance dynamics give the ground force s lam_des now: the force is affine in the
 * torques, lam = lam_0 + Lambda tau (three evaluations of the stance dynamics), tau = s t_1 - t_0 with
 * Lambda t_1 = lam_des and Lambda t_0 = lam_0, s the largest scale in [0, 1] within the torque limits. */
static void hop_stance_torques(const leg_params *P, const double *G, double s1, double c1, double s2, double c2, double w1,
                               double w2, double lam_x, double lam_y, double *tau)
{
    const leg_accel A0 = stance_core(P, s1, c1, s2, c2, w1, w2, 0.0, 0.0, 0.0);
    const leg_accel Ah = stance_core(P, s1, c1, s2, c2, w1, w2, 1.0, 0.0, 0.0);
    const leg_accel Ak = stance_core(P, s1, c1, s2, c2, w1, w2, 0.0, 1.0, 0.0);
    const double L11 = Ah.lam_x - A0.lam_x, L12 = Ak.lam_x - A0.lam_x; /* column j: per unit torque j */
    const double L21 = Ah.lam_y - A0.lam_y, L22 = Ak.lam_y - A0.lam_y;
    const double det = L11 * L22 - L12 * L21;
    const double t1[2] = {(L22 * lam_x - L12 * lam_y) / det, (L11 * lam_y - L21 * lam_x) / det};
    const double t0[2] = {(L22 * A0.lam_x - L12 * A0.lam_y) / det, (L11 * A0.lam_y - L21 * A0.lam_x) / det};
    const double lim[2] = {G[HG_LIM_HIP], G[HG_LIM_KNEE]};
    double s = INFINITY;
    for (int j = 0; j < 2; j++) {
        const double hi = t1[j] > 0.0 ? (lim[j] + t0[j]) / t1[j] : t1[j] < 0.0 ? (t0[j] - lim[j]) / t1[j] : INFINITY;
        s = hop_min(s, hi);
    }
    s = hop_clip(s, 0.0, 1.0);
    tau[0] = s * t1[0] - t0[0];
    tau[1] = s * t1[1] - t0[1];
}

/* One robot's torques tau (2) and its COM's horizontal velocity vx_com from the law's reading o (HOPPER_INPUTS) and
 * the COM's dead-reckoned drift x0; advances the apex bias, the last flight's apex (NaN before the first), the stance
 * phase, whether the last step was in flight and the time on the ground since the last touchdown. */
static void hopper_torque_one(const leg_params *P, const double *G, const double *o, double x0, double *bias, double *apex,
                              int64_t *phase, unsigned char *was_flight, double *since_touchdown, double *tau, double *vx_com_out)
{
    const leg_flight_inertia F = flight_inertia(P);
    const double m = F.m, a = F.a, b = F.b;
    const double l1 = P->l1, l2 = P->l2, g = P->g, dt = G[HG_DT];
    const double thb = o[HO_TH_B], q1 = o[HO_Q1], q2 = o[HO_Q2];
    const double vxb = o[HO_VX_B], vyb = o[HO_VY_B], wb = o[HO_W_B], wq1 = o[HO_W_Q1], wq2 = o[HO_W_Q2];
    const int contact = o[HO_CONTACT] > 0.5;
    const double command = o[HO_COMMAND];
    const double th1 = thb + q1, th2 = thb + q1 + q2;
    const double w1 = wb + wq1, w2 = wb + wq1 + wq2;
    const double s1 = sin(th1), c1 = cos(th1), s2 = sin(th2), c2 = cos(th2);
    /* COM relative to the hip (the base point) and its velocity, world axes */
    const double x_com_rel = (a * c1 + b * c2) / m;
    const double y_com = o[HO_BASE_Y] + (a * s1 + b * s2) / m; /* above the ground */
    const double vx_com = vxb - (a * s1 * w1 + b * s2 * w2) / m;
    const double vy_com = vyb + (a * c1 * w1 + b * c2 * w2) / m;
    const double rx = l1 * c1 + l2 * c2, ry = l1 * s1 + l2 * s2; /* foot relative to the hip */
    const double L = hypot(rx, ry);
    const double E_v = 0.5 * m * (vy_com * vy_com) + m * g * y_com;

    /* phases: touchdown starts a crouch and updates the apex bias with the last flight's apex */
    const double target = G[HG_Y_STAND] + command;
    const int touchdown = contact && *was_flight;
    if (touchdown && isfinite(*apex))
        *bias -= G[HG_APEX_GAIN] * (*apex - target);
    if (touchdown) {
        *phase = HOP_CROUCH;
        *since_touchdown = 0.0;
    }
    if (!contact)
        *apex = E_v / (m * g);
    *was_flight = !contact;
    const double E_star = m * g * (target + *bias);
    const double L_low = G[HG_L_LO] - G[HG_CROUCH0] - G[HG_CROUCH1] * command;
    const int stopped = contact && *phase == HOP_CROUCH && vy_com >= -0.05 && L < L_low + 0.03; /* the crouch's bottom */
    if (stopped && *since_touchdown >= G[HG_DWELL] - 1e-9)
        *phase = HOP_PUSH;
    const int dwelling = stopped && *phase == HOP_CROUCH; /* at the bottom, waiting out the dwell */
    if (contact)
        *since_touchdown += dt;
    if (contact && *phase == HOP_PUSH && (E_v >= E_star || q2 + wq2 * dt <= G[HG_Q2_LO]))
        *phase = HOP_RELEASE;

    /* 1. height: crouch (sink, then stop at L_low) or push (the energy deficit over the remaining rise) */
    const double d = hop_max(L - L_low, 0.0);
    const double v_des = -hop_min(G[HG_V_SINK], sqrt(2.0 * G[HG_A_C] * d));
    double a_crouch = G[HG_K_C] * (v_des - vy_com);
    const double a_stop = hop_min((vy_com * vy_com) / (2.0 * hop_max(d, 0.01)), 3.0 * g);
    if (vy_com < v_des)
        a_crouch = hop_max(a_crouch, a_stop);
    const double lam_crouch = hop_max(m * (g + a_crouch), 0.2 * m * g);
    const double phi = atan2(ry, rx); /* the leg's direction; at L_lo the thigh is at phi - alpha_lo */
    const double t1_lo = phi - G[HG_ALPHA_LO];
    const double y_lo = -G[HG_L_LO] * sin(phi) + (a * sin(t1_lo) + b * sin(t1_lo + G[HG_Q2_LO])) / m;
    const double rise = hop_max(hop_max(y_lo - y_com, vy_com * dt), G[HG_STROKE_MIN]);
    const double lam_push = hop_max(E_star - E_v, 0.0) / rise;
    const double lam_y = *phase == HOP_CROUCH ? lam_crouch : lam_push;
    /* 3. attitude: the ground force's moment about the COM steers H and the torso angle to zero */
    const double H = hop_angular_momentum(P, m, wb, w1, w2, s1, c1, s2, c2);
    double lam_x = (-G[HG_K_H] * H - G[HG_K_TH] * P->I_b * thb - (rx - x_com_rel) * lam_y) / y_com;
    if (dwelling) /* the COM held over the foot instead: a long stance on the point foot falls otherwise */
        lam_x = m * (-G[HG_DWELL_KP] * (x_com_rel - rx) - G[HG_DWELL_KD] * vx_com);
    const double cap = G[HG_FRICTION] * G[HG_MU] * lam_y;
    lam_x = hop_clip(lam_x, -cap, cap);
    double tau_stance[2];
    hop_stance_torques(P, G, s1, c1, s2, c2, w1, w2, lam_x, lam_y, tau_stance);

    /* 2. foot placement (flight, and the release): IK at L_td, computed-torque servo of the leg angles */
    const double L_td = G[HG_L_TD], knee = G[HG_KNEE_TD], alpha = G[HG_ALPHA_TD];
    const double v_star = hop_clip(-G[HG_K_X] * x0, -0.3, 0.3); /* back towards the start */
    const double dx_foot = vx_com * G[HG_T_S] / 2.0 + G[HG_K_V] * (vx_com - v_star);
    double com_des = x_com_rel, th1_d = 0.0, th2_d = 0.0;
    for (int k = 0; k < 2; k++) { /* the COM's offset from the hip at the target posture */
        const double fx = hop_clip(com_des + dx_foot, -0.6 * L_td, 0.6 * L_td);
        th1_d = atan2(-sqrt(hop_max(L_td * L_td - fx * fx, 1e-6)), fx) - alpha;
        th2_d = th1_d + knee;
        com_des = (a * cos(th1_d) + b * cos(th2_d)) / m;
    }
    const double dd1 = G[HG_K_P] * hop_wrap(th1_d - th1) - G[HG_K_D] * w1;
    const double dd2 = G[HG_K_P] * hop_wrap(th2_d - th2) - G[HG_K_D] * w2;
    const double K12 = F.kf * (c1 * c2 + s1 * s2);
    const double s12 = s1 * c2 - c1 * s2;
    const double tau_knee_f = K12 * dd1 + F.K22 * dd2 - F.kf * s12 * (w1 * w1);
    const double tau_hip_f = F.K11 * dd1 + K12 * dd2 + tau_knee_f + F.kf * s12 * (w2 * w2);

    *vx_com_out = vx_com;
    const int stance = contact && *phase != HOP_RELEASE;
    tau[0] = stance ? tau_stance[0] : tau_hip_f;
    tau[1] = stance ? tau_stance[1] : tau_knee_f;
}
