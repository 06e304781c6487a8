/* `looplab run services/examples/controller/pendulum_c.toml` builds it (the launch file's `build`, after
 * `cargo build --release`, which builds the library) and runs it.
 * The pendulum's built-in controller (shared/src/scenarios/pendulum/controller.rs) in C, the same
 * arithmetic in the same order: u = -(K·x) clamped to ±current_limit_a, x = the estimate minus the
 * upright reference, which is zero. -ffp-contract=off: no fused multiply-add, so the numbers are
 * the built-in's to the bit. */
#include <stdio.h>
#include "looplab_stage.h"

struct law { double gains[3], limit; };

static int step(void *user, double t, const double *x, size_t n_x, double *u, size_t n_u) {
    (void)t, (void)n_x, (void)n_u;
    const struct law *k = user;
    double current = -(k->gains[0] * x[0] + k->gains[1] * x[1] + k->gains[2] * x[2]);
    u[0] = current < -k->limit ? -k->limit : current > k->limit ? k->limit : current;
    return 0;
}

int main(void) {
    struct law k;
    if (looplab_config_f64("controller.gains.0", &k.gains[0]) || looplab_config_f64("controller.gains.1", &k.gains[1])
        || looplab_config_f64("controller.gains.2", &k.gains[2]) || looplab_config_f64("model.current_limit_a", &k.limit)) {
        fprintf(stderr, "error: the launch file needs controller.gains (3 numbers) and model.current_limit_a\n");
        return 2;
    }
    return looplab_run(step, &k);
}
