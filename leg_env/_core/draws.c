/* Draws made in compiled code from numpy generators: the uniforms of fresh starts and the robots of a
 * randomised batch (leg_env.randomize documents the draws and the rejection rule for users).
 *
 * A numpy BitGenerator hands out its C interface in a capsule named "BitGenerator" holding a bitgen_t
 * (numpy/random/bitgen.h); next_double() is what Generator.random() calls for each float64, so a draw
 * here takes the same numbers, and advances the generator the same way, as rng.random(out=...).
 *
 * Part of the unity build of module.c.
 */
#include <math.h>
#include <stdint.h>

#include "env.h"

typedef struct bitgen {
    void *state;
    uint64_t (*next_uint64)(void *st);
    uint32_t (*next_uint32)(void *st);
    double (*next_double)(void *st);
    uint64_t (*next_raw)(void *st);
} bitgen_t;

#define ROBOT_LIMITS 7       /* the limits of robot_params: hip_lo, hip_hi, knee_lo, knee_hi, min_base_height, nominal_knee, unilateral */
#define ROBOT_DRAWN_MAX 64   /* spec lines of one robot, at most */
#define DRAWS_MAX 1000000    /* most tries of draw_robots per robot: a bound on the work of one call */
/* the drawn fields: env_robot's doubles before q_nom (its parameters, mu, torque limits) */
#define ROBOT_DRAWN_FIELDS ((double)(offsetof(env_robot, q_nom) / sizeof(double)))

/* A drawn robot in `row` from the uniforms u of each spec line (the field's index among the doubles of
 * env_robot, its kind, low, high; kinds 0 scale, 1 offset, 2 range of the nominal `base`); then its
 * nominal posture, holding torques and COM. `limits` = (hip_lo, hip_hi, knee_lo, knee_hi,
 * min_base_height, nominal_knee, unilateral). Returns whether the robot is accepted: it can hold its
 * nominal posture within its torque limits, the posture is inside the task's limits, and on the
 * unilateral ground mu is below the Painleve bound there. The caller has checked every spec line. */
static int robot_params(const double *u, const double *spec, Py_ssize_t n_spec, const env_robot *base,
                        const double *limits, env_robot *r)
{
    *r = *base;
    double *row = (double *)r;
    const double *nominal = (const double *)base;
    for (Py_ssize_t f = 0; f < n_spec; f++) {
        const Py_ssize_t col = (Py_ssize_t)spec[4 * f];
        const int kind = (int)spec[4 * f + 1];
        const double lo = spec[4 * f + 2], hi = spec[4 * f + 3];
        const double x = lo + (hi - lo) * u[f]; /* numpy's uniform(lo, hi) from the same draw */
        if (kind == 0)
            row[col] = nominal[col] * x;
        else if (kind == 1)
            row[col] = nominal[col] + x;
        else
            row[col] = x;
    }
    double trig[4]; /* sin th1, cos th1, sin th2, cos th2 of the nominal posture */
    equilibrium_one(&r->p, limits[5], r->q_nom, r->tau_nom, trig);
    com_trig(&r->p, r->q_nom, NULL, trig[0], trig[1], trig[2], trig[3], r->com_nom, NULL);
    const double *q = r->q_nom;
    if (fabs(r->tau_nom[0]) > r->torque_limit[0] || fabs(r->tau_nom[1]) > r->torque_limit[1])
        return 0;
    if (q[3] < limits[0] || q[3] > limits[1] || q[4] < limits[2] || q[4] > limits[3] || q[1] < limits[4])
        return 0; /* the nominal posture would end the episode at once (the foot is at the origin) */
    if (limits[6] > 0.5) {
        const leg_response R = foot_response(&r->p, trig[0], trig[1], trig[2], trig[3]);
        if (R.Lxy != 0.0 && r->mu >= R.Lyy / fabs(R.Lxy))
            return 0;
    }
    return 1;
}
