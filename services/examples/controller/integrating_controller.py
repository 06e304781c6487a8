"""The pendulum's state feedback plus integral action on the angle estimate:
I = -(K X + k_i z), z = integral of theta dt. The integrator is state worth keeping: freeze and
thaw carry it across a restart of this process."""
import struct
import sys

import looplab

# k_i, A per rad·s: the sign of K's angle gain, slow beside the loop; the launch file's
# [parameters] ki (or --set parameters.ki=-10) changes it.
INTEGRAL_GAIN = -20.0


class IntegratingController:
    def __init__(self, stage):
        self.k1, self.k2, self.k3 = stage.config["controller"]["gains"]
        self.limit = stage.config["model"]["current_limit_a"]
        self.ki = stage.config.get("parameters", {}).get("ki", INTEGRAL_GAIN)
        self.integral = 0.0  # z, rad·s
        self.t_last = None  # the time of the last step, s

    def step(self, t, x, u):
        if self.t_last is not None:
            self.integral += x[0] * (t - self.t_last)
        self.t_last = t
        current = -(self.k1 * x[0] + self.k2 * x[1] + self.k3 * x[2] + self.ki * self.integral)
        u[0] = min(max(current, -self.limit), self.limit)

    def freeze(self):
        if self.t_last is None:
            return None  # no step yet: nothing to keep
        return struct.pack("<dd", self.integral, self.t_last)

    def thaw(self, data):
        self.integral, self.t_last = struct.unpack("<dd", data)
        print(f"thawed: integral {self.integral!r} rad·s at t = {self.t_last!r} s", file=sys.stderr)


looplab.run(IntegratingController)
