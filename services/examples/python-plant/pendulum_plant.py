"""The reaction-wheel pendulum's plant in Python (paper 003 §2), for a declared system's
`[plant] python = "pendulum_plant.py:Pendulum"`:

    J0 theta'' = m l g sin(theta) - tau
    phi''      = tau (1/J_r + 1/J0) - (m l g / J0) sin(theta),     tau = k I

State x = (theta, theta_dot, wheel_speed), input u = (current,). LoopLab integrates `derivative`
with its own RK4, the input held over each period. The arithmetic is the built-in model's
(shared/src/scenarios/pendulum/params.rs, Model::derivative), the same operations in the same
order, so the trajectory is byte-identical to the built-in pendulum's."""
import math


class Pendulum:
    def __init__(self, plant):  # plant.parameters: [plant.parameters] of the launch file
        p = plant.parameters
        self.j_r = p["j_r"]
        self.g = p["g"]
        self.torque_constant = p["torque_constant"]
        self.j0 = p["j_p"] + p["m_p"] * p["l_p"] * p["l_p"] + p["m_r"] * p["l_r"] * p["l_r"]
        self.ml = p["m_p"] * p["l_p"] + p["m_r"] * p["l_r"]

    def derivative(self, t, x, u, dx):  # x, u: float64 views; dx: the view to write x' into
        j0 = self.j0
        tau = self.torque_constant * u[0]
        gravity = self.ml * self.g * math.sin(x[0])
        dx[0] = x[1]
        dx[1] = (gravity - tau) / j0
        dx[2] = tau * (1.0 / self.j_r + 1.0 / j0) - gravity / j0
