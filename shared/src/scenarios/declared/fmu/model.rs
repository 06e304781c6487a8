//! The FMU as a [`PlantModel`]: Model Exchange hands LoopLab its derivatives, Co-Simulation steps
//! itself. Either saves and restores its whole state through the FMU's own serialisation where
//! the FMU offers it (`canSerializeFMUstate`).

use anyhow::{Context, Result, anyhow, bail};

use super::archive::Unpacked;
use super::description::Interface;
use super::ffi::Instance;
use super::{FmiKind, Mapping};
use crate::model::plant_model::{ModelSpec, PlantModel, Stepping};

pub struct FmuModel {
    // Dropped first: the instance is freed and the library closed before its folder is removed.
    instance: Instance,
    /// The unpacked FMU's folder, kept while the FMU may read its resources; an FMU without
    /// resources needs nothing of it once its binary is loaded, so it is removed at once (and a
    /// killed plant leaves nothing behind).
    _folder: Option<tempfile::TempDir>,
    describe: String,
    /// The FMU's file name, first in every error.
    label: String,
    kind: FmiKind,
    map: Mapping,
    can_serialize: bool,
    /// The FMU's own state and derivative vectors (Model Exchange), in its order.
    x: Vec<f64>,
    dx: Vec<f64>,
}

impl FmuModel {
    /// Instantiates, sets the parameters and the declared initial values, and initialises at t = 0.
    pub(super) fn new(
        unpacked: Unpacked,
        interface: Interface,
        kind: FmiKind,
        map: Mapping,
        spec: &ModelSpec,
        label: String,
        describe: String,
    ) -> Result<FmuModel> {
        let d = &unpacked.description;
        let me = kind == FmiKind::ModelExchange;
        let mut instance =
            Instance::new(d.version, &unpacked.binary(&interface.identifier), me, &d.token, &unpacked.resources())?;
        instance.set_reals(&map.real_parameters.0, &map.real_parameters.1).context("setting [plant.parameters]")?;
        instance
            .set_integers(&map.integer_parameters.0, &map.integer_parameters.1)
            .context("setting [plant.parameters]")?;
        let (vr, values): (Vec<u32>, Vec<f64>) =
            map.state.iter().zip(&spec.initial).filter_map(|(vr, x0)| x0.map(|x0| (*vr, x0))).unzip();
        instance.set_reals(&vr, &values).context("setting the declared initial state")?;
        instance.initialize(0.0).context("initialising")?;
        let n = d.states.len();
        Ok(FmuModel {
            instance,
            describe,
            label,
            kind,
            can_serialize: interface.can_serialize,
            map,
            x: vec![0.0; n],
            dx: vec![0.0; n],
            _folder: unpacked.has_resources().then_some(unpacked.folder),
        })
    }

    /// "pendulum.fmu: fmi2GetDerivatives returned fmi2Error at t = 1.234 s".
    fn at(&self, t: f64) -> impl Fn(anyhow::Error) -> anyhow::Error + '_ {
        move |e| anyhow!("{}: {e:#} at t = {t} s", self.label)
    }

    /// Model Exchange: the FMU at time t, state x (declared order), input u.
    fn set_point(&mut self, t: f64, x: &[f64], u: &[f64]) -> Result<()> {
        for (i, &j) in self.map.order.iter().enumerate() {
            self.x[j] = x[i];
        }
        self.instance.set_time_and_states(t, &self.x)?;
        self.instance.set_reals(&self.map.input, u)
    }
}

impl PlantModel for FmuModel {
    fn describe(&self) -> String {
        self.describe.clone()
    }

    fn stepping(&self) -> Stepping {
        match self.kind {
            FmiKind::ModelExchange => Stepping::Derivative,
            FmiKind::CoSimulation => Stepping::OwnStep,
        }
    }

    fn initial_state(&mut self) -> Result<Vec<f64>> {
        match self.kind {
            FmiKind::ModelExchange => {
                self.instance.continuous_states(&mut self.x)?;
                Ok(self.map.order.iter().map(|&j| self.x[j]).collect())
            }
            FmiKind::CoSimulation => {
                let mut x = vec![0.0; self.map.state.len()];
                self.instance.get_reals(&self.map.state, &mut x)?;
                Ok(x)
            }
        }
    }

    fn derivative(&mut self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) -> Result<()> {
        self.set_point(t, x, u).map_err(self.at(t))?;
        if let Err(e) = self.instance.derivatives(&mut self.dx) {
            return Err(self.at(t)(e));
        }
        for (i, &j) in self.map.order.iter().enumerate() {
            dx[i] = self.dx[j];
        }
        Ok(())
    }

    fn do_step(&mut self, t: f64, dt: f64, u: &[f64], x: &mut [f64]) -> Result<()> {
        let result = (|| {
            self.instance.set_reals(&self.map.input, u)?;
            self.instance.do_step(t, dt)?;
            self.instance.get_reals(&self.map.state, x)
        })();
        result.map_err(self.at(t))
    }

    fn outputs(&mut self, t: f64, x: &[f64], u: &[f64], y: &mut [f64]) -> Result<()> {
        if self.map.outputs.is_empty() {
            return Ok(());
        }
        let result = (|| {
            if self.kind == FmiKind::ModelExchange {
                self.set_point(t, x, u)?;
            }
            self.instance.get_reals(&self.map.outputs, y)
        })();
        result.map_err(self.at(t))
    }

    fn freeze(&mut self) -> Result<Option<Vec<u8>>> {
        if !self.can_serialize {
            return Ok(None);
        }
        self.instance.save().map(Some)
    }

    fn thaw(&mut self, frozen: &[u8]) -> Result<()> {
        if !self.can_serialize {
            bail!("{} cannot restore a saved state (canSerializeFMUstate is false)", self.describe);
        }
        self.instance.load(frozen)
    }

    fn set_state(&mut self, x: &[f64]) -> Result<()> {
        match self.kind {
            // Every derivative call sets the state; nothing else to restore.
            FmiKind::ModelExchange => Ok(()),
            FmiKind::CoSimulation => {
                let _ = x;
                bail!(
                    "{}: a Co-Simulation FMU's state cannot be set from a state vector, and no saved FMU state \
                     was found (it does not serialise its state, or its state is over the snapshot's 1 MiB)",
                    self.describe
                )
            }
        }
    }
}
