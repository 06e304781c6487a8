"""The pendulum's state feedback in Python: I = -K (X - X_d), X = (theta, theta_dot, wheel_speed),
upright and still X_d = 0, saturated to the motor controller's current limit."""
import looplab


class StateFeedback:
    def __init__(self, stage):
        config = dict(stage.config, **stage.config.get("parameters", {}))  # a declared system's [parameters]
        self.k1, self.k2, self.k3 = config["controller"]["gains"]
        self.limit = config["model"]["current_limit_a"]

    def step(self, t, x, u):  # x: the estimate (theta, theta_dot, wheel_speed, bias); u: (current,)
        current = -(self.k1 * x[0] + self.k2 * x[1] + self.k3 * x[2])
        u[0] = min(max(current, -self.limit), self.limit)


looplab.run(StateFeedback)
