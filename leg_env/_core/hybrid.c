/* The hybrid control step: exact unilateral contact with event-located transitions (leg_env.hybrid
 * documents it for users).
 *
 * The foot is in one of the modes stick, slip forward / backward, flight, carried as state with the
 * stick contact point `anchor` (anchor[1] is the ground's height). Each transition is a named witness
 * that fires when it goes from >= 0 to < 0 over an RK4 substep:
 *
 *   LIFTOFF        stick, slip   lam_y                   then the mode choice
 *   SLIP_ONSET     stick         mu lam_y - |lam_x|      then the mode choice
 *   SLIDING_STOP   slip          sigma x_f'              the sticking impulse, then the mode choice
 *   TOUCHDOWN      flight        y_f - ground            the impact map, then the mode choice
 *
 * A crossing is located by re-integrating the substep with a shorter length (Illinois regula falsi,
 * Newton on the foot height for a touchdown) until the bracket is shorter than LEG_ROOT_TIME.
 *
 * Part of the unity build of module.c.
 */
#include <math.h>

#include "robot.h"

/* Foot position and velocity of the integrator state. */
typedef struct {
    double x, y, vx, vy;
} leg_foot;

static inline leg_foot foot_of(const leg_model *M, const leg_x *X)
{
    leg_foot f;
    const double w1 = X->va + X->vb, w2 = w1 + X->vc;
    foot_velocity(&M->p, X->s1, X->c1, X->s2, X->c2, X->vx, X->vy, w1, w2, &f.vx, &f.vy);
    f.x = X->x + M->p.l1 * X->c1 + M->p.l2 * X->c2;
    f.y = X->y + M->p.l1 * X->s1 + M->p.l2 * X->s2;
    return f;
}

/* ---------------------------------------------------------------- witnesses (one per transition) */

/* Normal force: compressive (> 0) to tensile. */
static inline double liftoff_witness(double lam_y) { return lam_y; }

/* Sticking slack: the stick force leaves the friction cone. */
static inline double slip_onset_witness(double lam_x, double lam_y, double mu) { return mu * lam_y - fabs(lam_x); }

/* Sliding velocity sigma x_f': the slip comes to rest. */
static inline double sliding_stop_witness(double vfx, double sigma) { return sigma * vfx; }

/* Foot height above the ground: reaching it moving down. */
static inline double touchdown_witness(double y_f, double ground) { return y_f - ground; }

/* The mode's two witnesses at X (k: its derivative and force there); INFINITY fills a missing one.
 * stick: (LIFTOFF, SLIP_ONSET); slip: (LIFTOFF, SLIDING_STOP); flight: (TOUCHDOWN, -). */
static inline void witnesses(int mode, const leg_model *M, const leg_drive *u, const leg_x *X, const leg_accel *k,
                             const double *anchor, double *wa, double *wb)
{
    if (mode == LEG_FLIGHT) {
        *wa = touchdown_witness(X->y + M->p.l1 * X->s1 + M->p.l2 * X->s2, anchor[1]); /* foot_of's y */
        *wb = INFINITY;
    } else if (mode == LEG_STICK) {
        *wa = liftoff_witness(k->lam_y);
        *wb = slip_onset_witness(k->lam_x, k->lam_y, u->mu);
    } else {
        *wa = liftoff_witness(k->lam_y);
        *wb = sliding_stop_witness(foot_of(M, X).vx, slip_sigma(mode));
    }
}

static inline void event_kinds(int mode, int *kind_a, int *kind_b)
{
    if (mode == LEG_FLIGHT) {
        *kind_a = LEG_TOUCHDOWN;
        *kind_b = -1;
    } else if (mode == LEG_STICK) {
        *kind_a = LEG_LIFTOFF;
        *kind_b = LEG_SLIP_ONSET;
    } else {
        *kind_a = LEG_LIFTOFF;
        *kind_b = LEG_SLIDING_STOP;
    }
}

/* Whether a transition is watched: leaving contact is off once settled, everything past the hard cap. */
static inline int watched(int kind, int settled, int events)
{
    if (kind < 0 || events >= 2 * LEG_MAX_EVENTS)
        return 0;
    return !(settled && (kind == LEG_LIFTOFF || kind == LEG_SLIP_ONSET));
}

/* ---------------------------------------------------------------- reset maps and mode choice */

/* Apply the foot impulse M to X's velocity; book it and the kinetic energy it removes,
 * Delta T = M . (v_f- + v_f+) / 2. */
static leg_x kick(const leg_model *M, const leg_x *X, double Px, double Py, leg_tally *rec)
{
    const leg_response R = foot_response_m(M, X->s1, X->c1, X->s2, X->c2);
    const leg_foot before = foot_of(M, X);
    double d[LEG_NQ];
    impulse_velocity_m(M, &R, X->s1, X->c1, X->s2, X->c2, Px, Py, d);
    leg_x Y = *X;
    Y.vx += d[0];
    Y.vy += d[1];
    Y.va += d[2];
    Y.vb += d[3];
    Y.vc += d[4];
    const leg_foot after = foot_of(M, &Y);
    rec->kick[0] += Px;
    rec->kick[1] += Py;
    rec->impact_dissipation += -0.5 * (Px * (before.vx + after.vx) + Py * (before.vy + after.vy));
    return Y;
}

/* The sticking impulse -Lambda^-1 v_f: the foot at rest. */
static leg_x stop_foot(const leg_model *M, const leg_x *X, leg_tally *rec)
{
    const leg_response R = foot_response_m(M, X->s1, X->c1, X->s2, X->c2);
    const leg_foot f = foot_of(M, X);
    double Px, Py;
    impact_core(f.vx, f.vy, INFINITY, R.Lxx, R.Lxy, R.Lyy, &Px, &Py);
    return kick(M, X, Px, Py, rec);
}

/* The consistent mode at X, applying the impulses it needs: a foot above the ground, or leaving it,
 * flies; a foot hitting it gets the impact map first; a sliding foot slips or flies; a foot at rest
 * gets the one consistent mode (mode_at_rest). `mode` is the current one (a stick that stays keeps its
 * anchor), `exclude` a mode that a transition has just made inconsistent (or -1). Updates anchor[0]. */
static int choose_mode(int mode, leg_x *X, double *anchor, const leg_model *M, const leg_drive *u, int exclude,
                       int settled, leg_tally *rec, leg_hybrid_tangent *J)
{
    const double t_hip = u->tau_hip, t_knee = u->tau_knee, F = u->load_x, mu = u->mu;
    leg_foot f = foot_of(M, X);
    if (f.y - anchor[1] > LEG_GROUND_TOL || f.vy > LEG_REST_SPEED)
        return LEG_FLIGHT;
    const double s1 = X->s1, co1 = X->c1, s2 = X->s2, co2 = X->c2;
    if (f.vy < -LEG_REST_SPEED) { /* hitting the ground: the impact first */
        const leg_response R = foot_response_m(M, s1, co1, s2, co2);
        double Px, Py;
        if (impact_core(f.vx, f.vy, mu, R.Lxx, R.Lxy, R.Lyy, &Px, &Py) == LEG_IMPACT_PAINLEVE)
            rec->painleve += 1;
        if (J != NULL)
            impulse_tangent(M, X, mu, J);
        *X = kick(M, X, Px, Py, rec);
        f = foot_of(M, X);
    }
    const double w1 = X->va + X->vb, w2 = X->va + X->vb + X->vc;
    int new_mode = -1, painleve;
    if (fabs(f.vx) > LEG_REST_SPEED) {
        new_mode = mode_sliding_m(M, s1, co1, s2, co2, w1, w2, t_hip, t_knee, F, mu, f.vx > 0.0 ? 1.0 : -1.0, &painleve);
        if (painleve)
            rec->painleve += 1;
        if (new_mode < 0) { /* no consistent force: a tangential impact stops the foot */
            if (J != NULL)
                impulse_tangent(M, X, INFINITY, J);
            *X = stop_foot(M, X, rec);
        } else if (new_mode == LEG_FLIGHT && settled) {
            new_mode = f.vx > 0.0 ? LEG_SLIP_FORWARD : LEG_SLIP_BACKWARD;
            rec->settles += 1;
        }
    }
    if (new_mode < 0) { /* at rest */
        new_mode = mode_at_rest_m(M, s1, co1, s2, co2, w1, w2, t_hip, t_knee, F, mu, exclude, &painleve);
        if (painleve)
            rec->painleve += 1;
        if (new_mode == LEG_FLIGHT && settled) {
            new_mode = LEG_STICK;
            rec->settles += 1;
        }
    }
    if (new_mode == LEG_STICK) {
        const leg_foot g = foot_of(M, X);
        if (mode != LEG_STICK) {
            anchor[0] = g.x;
            if (J != NULL)
                anchor_tangent(&M->p, X, J);
        }
        if (g.vx != 0.0 || g.vy != 0.0) {
            if (J != NULL)
                impulse_tangent(M, X, INFINITY, J);
            *X = stop_foot(M, X, rec);
        }
    }
    return new_mode;
}

/* The earliest watched witness of a substep X -> X1 of length h at or past zero: the substep length s
 * (just past the root), the state and derivative there and the substep's sums; returns the event. In flight
 * the derivative is not formed (the touchdown witness needs none, and the caller forms the new mode's): k
 * then holds X1's. */
typedef struct {
    double s;
    leg_x X;
    leg_accel k;
    leg_sums sums;
    int rk4_steps; /* substeps re-integrated to locate it */
} leg_located;

static inline double watched_min(int watch_a, int watch_b, double wa, double wb)
{
    return leg_fmin(watch_a ? wa : INFINITY, watch_b ? wb : INFINITY);
}

static int locate(int mode, const leg_model *M, const leg_drive *u, const double *anchor, const leg_x *X,
                  const leg_accel *k, double h, const leg_x *X1, const leg_accel *k1, const leg_sums *sums1,
                  int watch_a, int watch_b, leg_located *out)
{
    double wa, wb;
    witnesses(mode, M, u, X, k, anchor, &wa, &wb);
    double fa = watched_min(watch_a, watch_b, wa, wb);
    witnesses(mode, M, u, X1, k1, anchor, &wa, &wb);
    double fb = watched_min(watch_a, watch_b, wa, wb);
    double a = 0.0, b = h;
    out->s = h;
    out->X = *X1;
    out->k = *k1;
    out->sums = *sums1;
    out->rk4_steps = 0;
    int side = 0;
    double s_next = -1.0; /* a Newton proposal for the touchdown witness, whose derivative is the foot's y velocity */
    for (int it = 0; it < LEG_ROOT_ITERATIONS; it++) {
        if (b - a <= LEG_ROOT_TIME)
            break;
        double s = (a < s_next && s_next < b) ? s_next : b - fb * (b - a) / (fb - fa);
        if (!(a < s && s < b))
            s = 0.5 * (a + b);
        leg_sums sums = {0.0, 0.0, 0.0};
        const leg_x Xs = rk4_substep(mode, M, u, anchor, X, k, s, &sums);
        out->rk4_steps += 1;
        /* the touchdown witness needs no derivative, and the caller reads none: flight skips it */
        const leg_accel ks = mode == LEG_FLIGHT ? *k1 : derivative(mode, M, u, &Xs);
        witnesses(mode, M, u, &Xs, &ks, anchor, &wa, &wb);
        const double fs = watched_min(watch_a, watch_b, wa, wb);
        if (fs < 0.0) {
            b = s;
            fb = fs;
            out->s = s;
            out->X = Xs;
            out->k = ks;
            out->sums = sums;
            if (side == -1)
                fa *= 0.5;
            side = -1;
        } else {
            a = s;
            fa = fs;
            if (side == 1)
                fb *= 0.5;
            side = 1;
        }
        s_next = -1.0;
        if (mode == LEG_FLIGHT) {
            const double vfy = foot_of(M, &Xs).vy;
            if (vfy < 0.0) /* Newton, nudged past the root so that the bracket closes */
                s_next = s - fs / vfy + (fs >= 0.0 ? 0.25 * LEG_ROOT_TIME : -0.25 * LEG_ROOT_TIME);
        }
    }
    witnesses(mode, M, u, &out->X, &out->k, anchor, &wa, &wb);
    int kind_a, kind_b;
    event_kinds(mode, &kind_a, &kind_b);
    if (watch_b && (!watch_a || wb < wa))
        return kind_b;
    return kind_a;
}

/* The reset map of event `kind` at X (just past it), then the mode choice; returns the new mode. */
static int transition(int kind, int mode, leg_x *X, double *anchor, const leg_model *M, const leg_drive *u,
                      int *settled, leg_tally *rec, leg_hybrid_tangent *J)
{
    if (kind == LEG_TOUCHDOWN) {
        const leg_foot f = foot_of(M, X);
        X->y = X->y - (f.y - anchor[1]);
        if (J != NULL)
            placement_tangent(&M->p, X, J);
        if (-f.vy < LEG_SETTLE_SPEED && !*settled) {
            *settled = 1;
            rec->settles += 1;
        }
    } else if (kind == LEG_SLIDING_STOP) {
        if (J != NULL)
            impulse_tangent(M, X, INFINITY, J);
        *X = stop_foot(M, X, rec);
    }
    return choose_mode(mode, X, anchor, M, u, kind != LEG_TOUCHDOWN ? mode : -1, *settled, rec, J);
}

/* Add a substep of length h in `mode` from X0 to X1 to the step's record. */
static inline void book(int mode, const leg_model *M, double h, const leg_x *X0, const leg_x *X1,
                        const leg_sums *sums, leg_tally *rec)
{
    rec->impulse[0] += h * sums->lx;
    rec->impulse[1] += h * sums->ly;
    if (mode == LEG_STICK) {
        rec->stick_time += h;
    } else if (mode == LEG_FLIGHT) {
        rec->flight_time += h;
    } else {
        rec->slip_time += h;
        rec->slip_distance += slip_sigma(mode) * (foot_of(M, X1).x - foot_of(M, X0).x);
        rec->slip_dissipation += h * sums->power;
    }
}

/* Where a control step has got to: the state, its derivative, the time taken and left, and the RK4
 * steps left by the step rule. */
typedef struct {
    leg_x X;
    leg_accel k;
    double t, t_left;
    int n_left;
    int rk4_steps; /* RK4 steps integrated so far: counted in this local, not through the tally's pointer */
} leg_progress;

/* A substep that ended with a watched witness below zero, not taken: its length, end state, the derivative there
 * (flight: not formed, the touchdown witness needs none) and sums, and which witnesses were watched. */
typedef struct {
    double h;
    leg_x X1;
    leg_accel k1;
    leg_sums sums;
    int watch_a, watch_b;
} leg_crossing;

/* Substeps in `mode` from g, booked, until the control step ends (returns 0) or a substep ends with a watched
 * witness below zero (returns 1, that substep left untaken in *c for locate()). w0a, w0b: the witnesses at g's
 * state, kept up to date. A witness is watched while the transition is (watched()) and the witness is at or above
 * zero at the substep's start; a foot that leaves the ground within LEG_GROUND_TOL below it (round-off of a contact
 * projection) is on it, so its touchdown is watched from there, or a fall back within the step would go
 * unlocated. Called with `mode` a constant (advance_in()), so that the compiler specialises the RK4 stages. */
LEG_INLINE int advance(int mode, const leg_model *M, const leg_drive *u, const double *anchor, leg_progress *g,
                       double *w0a, double *w0b, int settled, int events, leg_tally *rec, leg_crossing *c,
                       leg_hybrid_tangent *J)
{
    int kind_a, kind_b;
    event_kinds(mode, &kind_a, &kind_b);
    const int can_a = watched(kind_a, settled, events), can_b = watched(kind_b, settled, events);
    while (g->n_left > 0) {
        const double h = g->t_left / g->n_left;
        leg_sums sums = {0.0, 0.0, 0.0};
        const leg_x X1 = rk4_substep(mode, M, u, anchor, &g->X, &g->k, h, &sums);
        g->rk4_steps += 1;
        /* in flight the end state's derivative is formed only if another substep follows: the touchdown witness
         * needs none, and the step's last derivative is never read in flight */
        leg_accel k1 = g->k;
        if (mode != LEG_FLIGHT)
            k1 = derivative(mode, M, u, &X1);
        double w1a, w1b;
        witnesses(mode, M, u, &X1, &k1, anchor, &w1a, &w1b);
        const int watch_a = can_a && (*w0a >= 0.0 || (kind_a == LEG_TOUCHDOWN && *w0a >= -LEG_GROUND_TOL));
        const int watch_b = can_b && *w0b >= 0.0;
        if ((watch_a && w1a < 0.0) || (watch_b && w1b < 0.0)) {
            c->h = h;
            c->X1 = X1;
            c->k1 = k1;
            c->sums = sums;
            c->watch_a = watch_a;
            c->watch_b = watch_b;
            return 1;
        }
        book(mode, M, h, &g->X, &X1, &sums, rec);
        if (J != NULL) { /* h = t_left / n_left: an event earlier in the step moves it */
            double dh[LEG_NT];
            for (int j = 0; j < J->nd; j++)
                dh[j] = -J->dtime[j] / g->n_left;
            rk4_substep_tangent(J->nd, J->nd, mode, M, u, &g->X, h, &X1, J->dtau, J->danchor, J->timed ? dh : NULL, &J->T);
            if (J->timed)
                for (int j = 0; j < J->nd; j++)
                    J->dtime[j] += dh[j];
        }
        g->X = X1;
        g->t += h;
        g->t_left -= h;
        g->n_left -= 1;
        *w0a = w1a;
        *w0b = w1b;
        if (mode != LEG_FLIGHT)
            g->k = k1;
        else if (g->n_left > 0)
            g->k = derivative(mode, M, u, &X1);
    }
    return 0;
}

/* advance() in the mode `mode`, each mode a constant. */
static inline int advance_in(int mode, const leg_model *M, const leg_drive *u, const double *anchor, leg_progress *g,
                          double *w0a, double *w0b, int settled, int events, leg_tally *rec, leg_crossing *c,
                          leg_hybrid_tangent *J)
{
    switch (mode) {
    case LEG_STICK:
        return advance(LEG_STICK, M, u, anchor, g, w0a, w0b, settled, events, rec, c, J);
    case LEG_FLIGHT:
        return advance(LEG_FLIGHT, M, u, anchor, g, w0a, w0b, settled, events, rec, c, J);
    case LEG_SLIP_FORWARD:
        return advance(LEG_SLIP_FORWARD, M, u, anchor, g, w0a, w0b, settled, events, rec, c, J);
    default:
        return advance(LEG_SLIP_BACKWARD, M, u, anchor, g, w0a, w0b, settled, events, rec, c, J);
    }
}

/* The hybrid control step of hybrid_control_step(), and, with J, its tangent (tangent.c's leg_hybrid_tangent) carried
 * along: every substep taken, every located event (its time's derivative from its witness), every reset map. */
LEG_INLINE int hybrid_step_body(const leg_params *P, const leg_drive *u, double *q, double *qd, int mode, double *anchor,
                                double dt, int substeps, double max_angle, double s1, double co1, double s2, double co2,
                                leg_tally *rec, leg_log *log, leg_hybrid_tangent *J)
{
    leg_model model;
    model_init(&model, P);
    const leg_model *M = &model;
    memset(rec, 0, sizeof *rec);
    leg_progress g;
    g.X = x_from(q, qd, s1, co1, s2, co2);
    int settled = 0, events = 0;
    /* the mode under this step's torques: a stick that stays consistent, or a foot in the air, keeps its
     * mode without the full choice (the common cases); anything else goes through choose_mode() */
    g.k = derivative(mode, M, u, &g.X);
    int keep = 0;
    if (mode == LEG_STICK) {
        keep = g.k.lam_y >= 0.0 && u->mu * g.k.lam_y - fabs(g.k.lam_x) >= 0.0;
    } else if (mode == LEG_FLIGHT) {
        const leg_foot f = foot_of(M, &g.X);
        keep = f.y - anchor[1] > LEG_GROUND_TOL || f.vy > LEG_REST_SPEED;
    }
    if (!keep) {
        mode = choose_mode(mode, &g.X, anchor, M, u, -1, settled, rec, J);
        g.k = derivative(mode, M, u, &g.X);
    }
    g.t = 0.0;
    g.t_left = dt;
    g.rk4_steps = 0;
    g.n_left = substeps_for_rates(g.X.va, g.X.vb, g.X.vc, dt, substeps, max_angle);
    double w0a, w0b;
    witnesses(mode, M, u, &g.X, &g.k, anchor, &w0a, &w0b);
    leg_crossing c;
    while (advance_in(mode, M, u, anchor, &g, &w0a, &w0b, settled, events, rec, &c, J)) {
        leg_located at;
        const int kind = locate(mode, M, u, anchor, &g.X, &g.k, c.h, &c.X1, &c.k1, &c.sums, c.watch_a, c.watch_b, &at);
        if (J != NULL) {
            event_tangent(kind, mode, M, u, &g.X, at.s, &at.X, J);
            if (c.watch_a && c.watch_b) { /* both witnesses past zero at the located point: two events at once */
                double wa, wb;
                witnesses(mode, M, u, &at.X, &at.k, anchor, &wa, &wb);
                if (wa < 0.0 && wb < 0.0)
                    J->undefined |= LEG_D_SIMULTANEOUS;
            }
        }
        book(mode, M, at.s, &g.X, &at.X, &at.sums, rec);
        g.rk4_steps += at.rk4_steps;
        g.t += at.s;
        g.t_left -= at.s;
        if (log != NULL && events < LEG_LOG_SIZE) {
            log->event_time[events] = g.t;
            log->event_kind[events] = kind;
        }
        events += 1;
        if (events >= LEG_MAX_EVENTS && !settled) {
            settled = 1;
            rec->settles += 1;
        }
        g.X = at.X;
        mode = transition(kind, mode, &g.X, anchor, M, u, &settled, rec, J);
        /* the rest of the step in the new mode, by the step rule at the post-event rates */
        const int n_rule = substeps_for_rates(g.X.va, g.X.vb, g.X.vc, g.t_left, 1, max_angle);
        if (n_rule > g.n_left)
            g.n_left = n_rule;
        g.k = derivative(mode, M, u, &g.X);
        witnesses(mode, M, u, &g.X, &g.k, anchor, &w0a, &w0b);
    }
    if (mode != LEG_STICK)
        anchor[0] = foot_of(M, &g.X).x;
    rec->events = events;
    rec->rk4_steps = g.rk4_steps;
    rec->work = u->tau_hip * (g.X.b - q[3]) + u->tau_knee * (g.X.c - q[4]);
    rec->work_load = u->load_x * (g.X.x - q[0]); /* exact: F constant over the step, x_b continuous */
    x_to(&g.X, q, qd);
    if (J != NULL && (settled || rec->painleve > 0))
        J->undefined |= settled ? LEG_D_SETTLED : LEG_D_PAINLEVE;
    return mode;
}

/* One hybrid control step of one robot, in place; returns the mode at its end.
 * q, qd: the world state; anchor: the stick contact point (anchor[1] the ground's height; anchor[0] is
 * rewritten: the contact point in stick, else the foot's x); s1 .. co2: the sines/cosines of q's link
 * angles; rec: overwritten with what the step added up; log (NULL: none kept): each located transition's
 * kind and time written as it comes (the entries after the last are left as they were). */
static int hybrid_control_step(const leg_params *P, const leg_drive *u, double *q, double *qd, int mode,
                               double *anchor, double dt, int substeps, double max_angle, double s1, double co1,
                               double s2, double co2, leg_tally *rec, leg_log *log)
{
    return hybrid_step_body(P, u, q, qd, mode, anchor, dt, substeps, max_angle, s1, co1, s2, co2, rec, log, NULL);
}

/* hybrid_control_step() with its derivatives (row-major): A = d(q, qd) after / d(q, qd) before, (10, 10),
 * B = d(q, qd) after / d(tau_hip, tau_knee), (10, 2), and (Pj not NULL) Pj = d(q, qd) after / d(the parameters, mu),
 * (10, 12). follow: the anchor's x is the foot's of the state before the step (hybrid_step's default), so that it
 * moves with q; else it is held. Returns the LEG_D_* reasons the derivative does not exist (0: it does; else A, B and
 * Pj are NaN). */
static int hybrid_control_jacobians(const leg_params *P, const leg_drive *u, double *q, double *qd, int *mode, double *anchor,
                                    double dt, int substeps, double max_angle, double s1, double co1, double s2, double co2,
                                    int follow, leg_tally *rec, leg_log *log, double *A, double *B, double *Pj)
{
    leg_hybrid_tangent J;
    memset(&J, 0, sizeof J);
    const leg_x X = x_from(q, qd, s1, co1, s2, co2);
    tangent_start(P, &X, follow ? 1 : 0, &J.T, J.dtau, J.danchor);
    J.nd = Pj != NULL ? LEG_NDP : LEG_ND;
    *mode = hybrid_step_body(P, u, q, qd, *mode, anchor, dt, substeps, max_angle, s1, co1, s2, co2, rec, log, &J);
    tangent_out(&J.T, J.undefined ? NAN : 0.0, A, B, Pj);
    return J.undefined;
}
