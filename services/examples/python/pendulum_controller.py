"""The pendulum's state feedback in Python: I = -K (X - X_d), X = (theta, theta_dot, wheel_speed),
upright and still X_d = 0, saturated to the motor controller's current limit."""
import looplab


def section(config, name):
    """The launch file's [name], or a declared system's [parameters.name]."""
    return config["parameters"][name] if name in config.get("parameters", {}) else config[name]


class StateFeedback:
    def __init__(self, stage):
        self.k1, self.k2, self.k3 = section(stage.config, "controller")["gains"]
        self.limit = section(stage.config, "model")["current_limit_a"]

    def step(self, t, x, u):  # x: the estimate (theta, theta_dot, wheel_speed, bias); u: (current,)
        current = -(self.k1 * x[0] + self.k2 * x[1] + self.k3 * x[2])
        u[0] = min(max(current, -self.limit), self.limit)


looplab.run(StateFeedback)
