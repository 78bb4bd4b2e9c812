/* The planar floating-base leg: the structs every kernel of the compiled core shares.
 *
 * Conventions (leg_env.physics.dynamics states them for users, the lesson's sections 1-5):
 *   q = [x_b, y_b, th_b, q1, q2]: torso COM position (the hip sits there), torso angle, hip angle
 *   (thigh relative to torso), knee angle (shank relative to thigh). Absolute link angles
 *   th1 = th_b + q1, th2 = th1 + q2.  M(q) qdd + h(q, qd) = S^T tau + Jc^T lam, h holding Coriolis,
 *   centrifugal and gravity terms; lam = [lam_x, lam_y] is the ground's force on the foot.
 *
 * The structs Python reads are field lists (fields.h): leg_env.physics.layout builds their numpy dtypes from the
 * layouts the compiled module reports (kernels.layouts()), so that each layout is written here only.
 */
#ifndef LEG_ROBOT_H
#define LEG_ROBOT_H

#include <stdint.h>

#include "fields.h"

/* Inlined into every caller: the RK4 stages of one contact mode then compile to straight-line code of that
 * mode's dynamics (the compiler's own heuristics leave the three-mode dispatch out of line). */
#if defined(_MSC_VER)
#define LEG_INLINE static __forceinline
#else
#define LEG_INLINE static inline __attribute__((always_inline))
#endif

/* C99's fmax and fmin, inlined: without -ffinite-math-only the compiler calls libm's. A NaN argument gives the
 * other one; otherwise the larger (smaller), and the second argument on a tie (+0 and -0), as libm on x86-64. */
static inline double leg_fmax(double a, double b)
{
    if (a != a)
        return b;
    if (b != b)
        return a;
    return a > b ? a : b;
}

static inline double leg_fmin(double a, double b)
{
    if (a != a)
        return b;
    if (b != b)
        return a;
    return a < b ? a : b;
}

#define LEG_NQ 5 /* generalised coordinates */
#define LEG_NU 2 /* actuated joints */

/* Masses [kg], inertias [kg m^2], lengths [m] and gravity [m/s^2]: LegParams, field for field. */
typedef struct {
    LEG_PARAMS_FIELDS(FIELD_DECLARE, , )
} leg_params;
#define LEG_N_PARAMS 11 /* leg_params is LegParams.array as it is: eleven doubles, no padding */

/* What is held over a control step besides the state: joint torques, a horizontal force on the
 * torso's COM (a push), and the ground's friction coefficient. */
typedef struct {
    double tau_hip, tau_knee; /* [N m] */
    double load_x;            /* [N] */
    double mu;                /* [1] */
} leg_drive;

/* Contact modes of the foot (leg_env.contact). */
typedef enum { LEG_STICK = 0, LEG_SLIP_FORWARD = 1, LEG_SLIP_BACKWARD = 2, LEG_FLIGHT = 3 } leg_mode;
#define LEG_N_MODES 4 /* the contact modes */

/* Located transitions (leg_env.hybrid), one witness each. */
typedef enum { LEG_LIFTOFF = 0, LEG_SLIP_ONSET = 1, LEG_SLIDING_STOP = 2, LEG_TOUCHDOWN = 3 } leg_event;

/* Status of a foot impact (contact.c). */
typedef enum { LEG_IMPACT_NONE = 0, LEG_IMPACT_STICK = 1, LEG_IMPACT_SLIDE = 2, LEG_IMPACT_PAINLEVE = 3 } leg_impact;

#define LEG_MAX_EVENTS 8                    /* located events per control step before a Zeno settle */
#define LEG_LOG_SIZE (2 * LEG_MAX_EVENTS)   /* events per step can reach 2 LEG_MAX_EVENTS */
#define LEG_GROUND_TOL 1e-9                 /* a foot within this height of the ground is on it [m] */
#define LEG_SETTLE_SPEED 1e-6               /* a slower touchdown settles the robot into contact [m/s] */
#define LEG_ROOT_TIME 1e-12                 /* event location: bracket length [s] */
#define LEG_ROOT_ITERATIONS 100
#define LEG_REST_SPEED 1e-9                 /* a foot slower than this counts as at rest [m/s] */
#define LEG_MAX_SUBSTEPS 4096               /* most RK4 steps per control step */

/* The integrator's state: q, qd and the sines and cosines of th1 and th2 (kept up to date by the
 * integrator, so that no RK4 stage calls sin or cos). */
typedef struct {
    double x, y, a, b, c;      /* q = (x_b, y_b, th_b, q1, q2) */
    double vx, vy, va, vb, vc; /* qd */
    double s1, c1, s2, c2;     /* sin th1, cos th1, sin th2, cos th2 */
} leg_x;

/* Accelerations and contact force of one mode at one state. */
typedef struct {
    double xdd, ydd, thbdd, q1dd, q2dd; /* qdd */
    double lam_x, lam_y;                /* ground force on the foot [N] */
} leg_accel;

/* What one hybrid control step adds up (leg_env.physics.hybrid.HybridStep's sums and counts); an environment's
 * env_out holds one, which the step writes in place. */
typedef struct {
    LEG_TALLY_FIELDS(FIELD_DECLARE, , )
} leg_tally;

/* The located transitions of one hybrid control step, in order. */
typedef struct {
    LEG_LOG_FIELDS(FIELD_DECLARE, , )
} leg_log;

/* What one hybrid control step did (leg_env.physics.hybrid.HybridStep). */
typedef struct {
    LEG_RECORD_FIELDS(FIELD_DECLARE, , )
} leg_record;

#endif
