//! The run's vectors as the recorder and the replay read them: names, units and sizes of the state, each
//! sensor's reading, the estimate and the input, taken once from the launch file and the
//! scenario; and the column names of `trajectory.csv` made from them.

use crate::config::launch::LaunchConfig;
use crate::config::schema::Component;
use crate::model::scenario::Scenario;

#[derive(Debug, Clone, Default, PartialEq)]
pub struct VectorLayout {
    pub state: Vec<Component>,
    /// Per sensor, in the launch file's order (the order of readings in `Measurements`): its
    /// name and its components.
    pub sensors: Vec<(String, Vec<Component>)>,
    pub estimate: Vec<Component>,
    pub input: Vec<Component>,
}

impl VectorLayout {
    /// A small made-up layout for the sinks' unit tests: two state components, two sensors
    /// (one scalar, one of two components), one estimate, one input.
    #[doc(hidden)]
    pub fn example() -> Self {
        let c = Component::new;
        VectorLayout {
            state: vec![c("theta", "rad"), c("omega", "rad/s")],
            sensors: vec![
                ("encoder".into(), vec![c("angle", "rad")]),
                ("imu".into(), vec![c("x", "m/s²"), c("y", "1")]),
            ],
            estimate: vec![c("theta", "rad")],
            input: vec![c("u", "N·m")],
        }
    }

    pub fn new(config: &LaunchConfig, scenario: &dyn Scenario) -> Self {
        let vectors = scenario.vectors();
        Self {
            state: vectors.state.to_vec(),
            sensors: config
                .sensors
                .iter()
                .map(|(name, spec)| (name.clone(), config.signal_of(spec).components.to_vec()))
                .collect(),
            estimate: vectors.estimate.to_vec(),
            input: vectors.input.to_vec(),
        }
    }

    /// The number of components of each sensor's reading.
    pub fn sensor_dims(&self) -> Vec<usize> {
        self.sensors.iter().map(|(_, components)| components.len()).collect()
    }

    /// The header of `trajectory.csv`: `k`, `t_s`, the state, each sensor's reading (`meas.` and
    /// the sensor's name, then `.` and the component's name when it has more than one), the
    /// estimate (`est.`), the command (`cmd.`) and the input the actuator applied (`applied.`),
    /// each with its unit.
    pub fn trajectory_columns(&self) -> Vec<String> {
        self.trajectory_columns_with_units().into_iter().map(|(name, _)| name).collect()
    }

    /// [`VectorLayout::trajectory_columns`], each with its component's unit as written ("rad/s";
    /// "" for k).
    pub fn trajectory_columns_with_units(&self) -> Vec<(String, &'static str)> {
        let column = |name: &str, unit: &'static str| (column_name(name, unit), unit);
        let mut columns = vec![("k".to_string(), ""), column("t", "s")];
        columns.extend(self.state.iter().map(|c| column(c.name, c.unit)));
        for (sensor, components) in &self.sensors {
            match &components[..] {
                [c] => columns.push(column(&format!("meas.{sensor}"), c.unit)),
                components => {
                    columns.extend(components.iter().map(|c| column(&format!("meas.{sensor}.{}", c.name), c.unit)))
                }
            }
        }
        columns.extend(self.estimate.iter().map(|c| column(&format!("est.{}", c.name), c.unit)));
        columns.extend(self.input.iter().map(|c| column(&format!("cmd.{}", c.name), c.unit)));
        columns.extend(self.input.iter().map(|c| column(&format!("applied.{}", c.name), c.unit)));
        columns
    }
}

/// A CSV column's name: `name`, then `_` and the unit spelt in ASCII snake case (`rad/s` →
/// `rad_per_s`, `N·m` → `N_m`, `1/(kg·m²)` → `per_kg_m2`); a pure number ("1" or "") has none.
/// Spreadsheets, pandas and shells all take such a name as it is.
pub fn column_name(name: &str, unit: &str) -> String {
    let ascii = |part: &str| part.replace('·', "_").replace('²', "2").replace('³', "3").replace(['(', ')'], "");
    let suffix = match unit.split_once('/') {
        _ if unit == "1" || unit.is_empty() => return name.to_string(),
        None => ascii(unit),
        Some(("1", per)) => format!("per_{}", ascii(per)),
        Some((unit, per)) => format!("{}_per_{}", ascii(unit), ascii(per)),
    };
    format!("{name}_{suffix}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn column_names_spell_every_unit_in_ascii() {
        let cases = [
            ("theta", "rad", "theta_rad"),
            ("theta_dot", "rad/s", "theta_dot_rad_per_s"),
            ("tau_alpha_r", "N·m", "tau_alpha_r_N_m"),
            ("vx", "m/s", "vx_m_per_s"),
            ("mass", "kg", "mass_kg"),
            ("current", "A", "current_A"),
            ("ax", "m/s²", "ax_m_per_s2"),
            ("jerk", "m/s³", "jerk_m_per_s3"),
            ("inertia", "kg·m²", "inertia_kg_m2"),
            ("inv_mass", "1/kg", "inv_mass_per_kg"),
            ("inv_inertia", "1/(kg·m²)", "inv_inertia_per_kg_m2"),
            ("gain", "1", "gain"),
            ("count", "", "count"),
        ];
        for (name, unit, column) in cases {
            assert_eq!(column_name(name, unit), column, "{name} in {unit}");
        }
    }

    #[test]
    fn the_example_layout_has_these_columns() {
        assert_eq!(
            VectorLayout::example().trajectory_columns(),
            [
                "k",
                "t_s",
                "theta_rad",
                "omega_rad_per_s",
                "meas.encoder_rad",
                "meas.imu.x_m_per_s2",
                "meas.imu.y",
                "est.theta_rad",
                "cmd.u_N_m",
                "applied.u_N_m"
            ]
        );
    }
}
