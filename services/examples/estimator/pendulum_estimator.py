"""The pendulum's bias observer in Python (shared/src/scenarios/pendulum/estimator.rs).

The encoder reads y = theta + delta. The observer on x = (theta, theta_dot, delta), with the
innovation e = x1 + x3 - y:
    x1' = x2 - l1 e
    x2' = a sin(y - x3) + b I - l2 e
    x3' = -l3 e
is integrated with RK4 over each interval between encoder readings, the newest reading and the
applied current I held. The wheel speed is measured: it passes through. The bias estimate is
kept across a restart (freeze/thaw), as the built-in estimator keeps it."""
import math
import struct

import looplab

SUBSTEPS = 4  # RK4 steps per interval


def observer_gains(a, poles):
    """(l1, l2, l3) that place the error poles at cos(y - x3) = 1."""
    p1, p2, p3 = poles
    c2 = -(p1 + p2 + p3)
    c1 = p1 * p2 + p1 * p3 + p2 * p3
    c0 = -(p1 * p2 * p3)
    l3 = -c0 / a
    return (c2 - l3, c1, l3)


def sensor_of(config, signal):
    """The name of the sensor that reads `signal` (a scenario's `signal`, a declared system's `reads`)."""
    reads = lambda sensor: sensor.get("signal") or sensor["reads"][0].split(".")[-1]
    return next(name for name, sensor in config["sensors"].items() if reads(sensor) == signal)


class BiasObserver:
    def __init__(self, stage):
        # A scenario's launch file, or a declared system's [parameters] table.
        config = dict(stage.config, **stage.config.get("parameters", {}))
        if config["estimator"]["kind"] != "bias-observer":
            raise ValueError("this estimator is the bias observer: set estimator.kind = \"bias-observer\"")
        m = config["model"]
        j0 = m["j_p"] + m["m_p"] * m["l_p"] * m["l_p"] + m["m_r"] * m["l_r"] * m["l_r"]
        ml = m["m_p"] * m["l_p"] + m["m_r"] * m["l_r"]
        self.a = ml * m["g"] / j0  # gravity's gain, 1/s²
        self.b = -m["torque_constant"] / j0  # the current's gain, rad/(s²·A)
        observer = config["estimator"]["bias-observer"]
        self.l = observer.get("gains") or observer_gains(self.a, observer["poles"])
        # Where the numbers are in the step's input: each sensor's value, valid, fresh, sample_time.
        names = stage.input_names
        encoder, speed = sensor_of(config, "theta"), sensor_of(config, "wheel_speed")
        self.y, self.y_valid = names.index(f"{encoder}.theta"), names.index(f"{encoder}.valid")
        self.speed, self.speed_valid = names.index(f"{speed}.wheel_speed"), names.index(f"{speed}.valid")
        self.current = names.index("u_applied.current")
        self.x = (0.0, 0.0, 0.0)  # (theta, theta_dot, delta) estimates
        self.t_last = None  # when x holds; None until the first encoder reading
        self.resumed_bias = 0.0  # a restarted observer starts from its predecessor's delta

    def derivative(self, x, y, current):
        l1, l2, l3 = self.l
        e = x[0] + x[2] - y
        return (x[1] - l1 * e, self.a * math.sin(y - x[2]) + self.b * current - l2 * e, -l3 * e)

    def propagate(self, x, y, current, duration):
        h = duration / SUBSTEPS
        for _ in range(SUBSTEPS):  # classical RK4
            k1 = self.derivative(x, y, current)
            k2 = self.derivative([xi + ki * (h / 2.0) for xi, ki in zip(x, k1)], y, current)
            k3 = self.derivative([xi + ki * (h / 2.0) for xi, ki in zip(x, k2)], y, current)
            k4 = self.derivative([xi + ki * h for xi, ki in zip(x, k3)], y, current)
            x = tuple(xi + (a + b * 2.0 + c * 2.0 + d) * (h / 6.0) for xi, a, b, c, d in zip(x, k1, k2, k3, k4))
        return x

    def step(self, t, readings, estimate):
        if readings[self.y_valid]:
            y = readings[self.y]
            if self.t_last is None:  # start from the reading, at rest, with the bias known so far
                self.x = (y - self.resumed_bias, 0.0, self.resumed_bias)
            else:
                self.x = self.propagate(self.x, y, readings[self.current], t - self.t_last)
            self.t_last = t
        theta, theta_dot, delta = self.x
        wheel_speed = readings[self.speed] if readings[self.speed_valid] else 0.0
        estimate[0], estimate[1], estimate[2], estimate[3] = theta, theta_dot, wheel_speed, delta

    def freeze(self):
        return None if self.t_last is None else struct.pack("<d", self.x[2])

    def thaw(self, data):
        (self.resumed_bias,) = struct.unpack("<d", data)


looplab.run(BiasObserver)
