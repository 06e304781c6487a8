//! Which pair of flat outputs the tethered robot's controller tracks (section IV). The
//! controller and the reference both depend on it, so it sits below both.

use serde::Deserialize;

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, strum::Display)]
#[serde(rename_all = "kebab-case")]
#[strum(serialize_all = "kebab-case")]
pub enum Law {
    /// Γa′: ϕ and ϑ.
    GammaA,
    /// Γb: ϕ and f_L.
    GammaB,
}
