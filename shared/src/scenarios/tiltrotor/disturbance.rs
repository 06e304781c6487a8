//! (placeholder until the helper's version lands) External force on x, y, z.

use serde::Deserialize;

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DisturbanceSection {
    pub steps: Vec<[f64; 4]>,
    pub pulses: Vec<[f64; 5]>,
}

impl DisturbanceSection {
    pub fn force(&self, t: f64) -> [f64; 3] {
        let mut f = [0.0; 3];
        for s in &self.steps {
            if t >= s[0] {
                for i in 0..3 {
                    f[i] += s[1 + i];
                }
            }
        }
        f
    }
}
