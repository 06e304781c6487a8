/* The reaction-wheel pendulum (paper 003 §2) for the FMI 2.0 and 3.0 wrappers (fmi2.c, fmi3.c).
 *
 * derivative() does the SAME floating-point operations in the same order as
 * shared/src/scenarios/pendulum/params.rs `Model::derivative` (and energy() as `Model::energy`), so
 * Model Exchange gives LoopLab's built-in pendulum bit for bit. Build with -ffp-contract=off (no
 * fused multiply-adds) and without -ffast-math. Co-Simulation: classical RK4 inside doStep with the
 * input held, `substeps` equal steps per communication step, in the same order as
 * shared/src/model/integrate.rs.
 *
 * Value references (the same in both FMI versions):
 *   0 time; 1 theta, 2 theta_dot, 3 wheel_speed (the continuous states); 4..6 their derivatives;
 *   7 current (input, A); 8 energy (output, J); 10..17 the parameters m_p, l_p, j_p, m_r, l_r, j_r,
 *   g, torque_constant; 20 substeps (Co-Simulation's RK4 steps per doStep). */

#ifndef LOOPLAB_PENDULUM_H
#define LOOPLAB_PENDULUM_H

#include <math.h>
#include <stdlib.h>
#include <string.h>

enum { VR_TIME = 0, VR_X = 1, VR_DER = 4, VR_CURRENT = 7, VR_ENERGY = 8, VR_PARAM = 10, N_PARAM = 8, VR_SUBSTEPS = 20 };
enum { M_P, L_P, J_P, M_R, L_R, J_R, G, TORQUE_CONSTANT };

/* Plain data: an FMU state is a copy of it, its serialisation its bytes. */
typedef struct {
    double time;
    double x[3];
    double current;
    double p[N_PARAM];
    int substeps;
} Pendulum;

static void pendulum_defaults(Pendulum *s) {
    static const double p[N_PARAM] = {0.58, 0.10, 3.8e-3, 0.35, 0.22, 12.48e-4, 9.81, 0.0369};
    memset(s, 0, sizeof *s);
    memcpy(s->p, p, sizeof p);
    s->x[0] = 0.05;
    s->substeps = 10;
}

static double pendulum_j0(const double *p) {
    return p[J_P] + p[M_P] * p[L_P] * p[L_P] + p[M_R] * p[L_R] * p[L_R];
}

static double pendulum_ml(const double *p) {
    return p[M_P] * p[L_P] + p[M_R] * p[L_R];
}

static void pendulum_derivative(const double *p, const double *x, double current, double *dx) {
    double j0 = pendulum_j0(p);
    double tau = p[TORQUE_CONSTANT] * current;
    double gravity = pendulum_ml(p) * p[G] * sin(x[0]);
    dx[0] = x[1];
    dx[1] = (gravity - tau) / j0;
    dx[2] = tau * (1.0 / p[J_R] + 1.0 / j0) - gravity / j0;
}

static double pendulum_energy(const double *p, const double *x) {
    double wheel_abs = x[1] + x[2];
    return 0.5 * pendulum_j0(p) * x[1] * x[1] + 0.5 * p[J_R] * wheel_abs * wheel_abs + pendulum_ml(p) * p[G] * cos(x[0]);
}

/* x + k * c, component by component (nalgebra's `x + k * c`). */
static void axpy(const double *x, const double *k, double c, double *out) {
    for (int i = 0; i < 3; i++) out[i] = x[i] + k[i] * c;
}

/* integrate.rs `rk4`: `substeps` RK4 steps of h = duration / substeps. */
static void pendulum_rk4(Pendulum *s, double duration) {
    int n = s->substeps < 1 ? 1 : s->substeps;
    double h = duration / (double)n;
    double k1[3], k2[3], k3[3], k4[3], tmp[3];
    for (int step = 0; step < n; step++) {
        pendulum_derivative(s->p, s->x, s->current, k1);
        axpy(s->x, k1, h / 2.0, tmp);
        pendulum_derivative(s->p, tmp, s->current, k2);
        axpy(s->x, k2, h / 2.0, tmp);
        pendulum_derivative(s->p, tmp, s->current, k3);
        axpy(s->x, k3, h, tmp);
        pendulum_derivative(s->p, tmp, s->current, k4);
        for (int i = 0; i < 3; i++) s->x[i] = s->x[i] + (k1[i] + k2[i] * 2.0 + k3[i] * 2.0 + k4[i]) * (h / 6.0);
    }
}

/* The value of a Float64 / Real variable; 0 on success, -1 for an unknown reference. */
static int pendulum_get(const Pendulum *s, unsigned vr, double *value) {
    double dx[3];
    if (vr == VR_TIME) *value = s->time;
    else if (vr >= VR_X && vr < VR_X + 3) *value = s->x[vr - VR_X];
    else if (vr >= VR_DER && vr < VR_DER + 3) {
        pendulum_derivative(s->p, s->x, s->current, dx);
        *value = dx[vr - VR_DER];
    } else if (vr == VR_CURRENT) *value = s->current;
    else if (vr == VR_ENERGY) *value = pendulum_energy(s->p, s->x);
    else if (vr >= VR_PARAM && vr < VR_PARAM + N_PARAM) *value = s->p[vr - VR_PARAM];
    else return -1;
    return 0;
}

/* Sets a Float64 / Real variable: the states, the input, the parameters. */
static int pendulum_set(Pendulum *s, unsigned vr, double value) {
    if (vr >= VR_X && vr < VR_X + 3) s->x[vr - VR_X] = value;
    else if (vr == VR_CURRENT) s->current = value;
    else if (vr >= VR_PARAM && vr < VR_PARAM + N_PARAM) s->p[vr - VR_PARAM] = value;
    else return -1;
    return 0;
}

#endif
