"""Ideal sensors: every reading is the true state's component of the same name, fresh and valid at
every loop (no noise, bias, quantisation or delay): a reference to judge an estimator against."""
import looplab


class IdealSensors:
    def __init__(self, stage):
        state = {name: i for i, name in enumerate(stage.input_names)}
        # Each output "<sensor>.<component>" reads the state's "<component>"; the sensor's valid,
        # fresh and sample_time keep what the runner starts them at (1, 1, t).
        self.copies = [(o, state[name.split(".", 1)[1]]) for o, name in enumerate(stage.output_names)
                       if name.split(".", 1)[1] in state]

    def step(self, t, x, u):
        for o, i in self.copies:
            u[o] = x[i]


looplab.run(IdealSensors)
