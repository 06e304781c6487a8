//! What LoopLab needs of an FMU's modelDescription.xml, read with `fmi-schema` for FMI 2.0 and 3.0
//! into one shape: the interfaces it offers, its scalar variables, its continuous states.

use fmi_schema::fmi2::{Causality as Causality2, Fmi2ModelDescription, ScalarVariableElement};
use fmi_schema::fmi3::{
    AbstractVariableTrait, Causality as Causality3, Fmi3ModelDescription, Variable as Var3, VariableDependency,
};
use fmi_schema::minimal::MinModelDescription;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Version {
    Fmi2,
    Fmi3,
}

impl Version {
    pub fn label(self) -> &'static str {
        match self {
            Version::Fmi2 => "FMI 2.0",
            Version::Fmi3 => "FMI 3.0",
        }
    }
}

/// One of the FMU's interfaces (Model Exchange or Co-Simulation).
#[derive(Debug, Clone)]
pub struct Interface {
    /// The binary's file name without extension.
    pub identifier: String,
    pub can_serialize: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Causality {
    Parameter,
    Input,
    Output,
    Local,
    Other,
}

/// The value type, as far as LoopLab sets and reads it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Real (FMI 2) or Float64 (FMI 3).
    Real,
    /// Integer (FMI 2) or Int32 (FMI 3).
    Integer,
    Other,
}

#[derive(Debug, Clone)]
pub struct Variable {
    pub name: String,
    pub vr: u32,
    pub causality: Causality,
    pub kind: Kind,
    /// A scalar (FMI 3 arrays are not mapped).
    pub scalar: bool,
}

#[derive(Debug, Clone)]
pub struct Description {
    pub version: Version,
    /// FMI 2 guid or FMI 3 instantiationToken.
    pub token: String,
    pub model_exchange: Option<Interface>,
    pub co_simulation: Option<Interface>,
    pub variables: Vec<Variable>,
    /// The continuous states' value references, in the FMU's state-vector order.
    pub states: Vec<u32>,
}

impl Description {
    pub fn parse(xml: &str) -> Result<Description, String> {
        let min: MinModelDescription = fmi_schema::deserialize(xml).map_err(|e| e.to_string())?;
        match min.fmi_version.split('.').next() {
            Some("2") => from_fmi2(&fmi_schema::deserialize(xml).map_err(|e| e.to_string())?),
            Some("3") => from_fmi3(&fmi_schema::deserialize(xml).map_err(|e| e.to_string())?),
            _ => Err(format!("fmiVersion \"{}\" (LoopLab reads FMI 2.0 and 3.0)", min.fmi_version)),
        }
    }

    pub fn by_name(&self, name: &str) -> Option<&Variable> {
        self.variables.iter().find(|v| v.name == name)
    }

    /// The names of the variables `keep` selects, for an error message ("a, b, c" or "none").
    pub fn names(&self, keep: impl Fn(&Variable) -> bool) -> String {
        let names: Vec<&str> = self.variables.iter().filter(|v| keep(v)).map(|v| v.name.as_str()).collect();
        if names.is_empty() { "none".into() } else { names.join(", ") }
    }
}

fn from_fmi2(md: &Fmi2ModelDescription) -> Result<Description, String> {
    let variables: Vec<Variable> = md
        .model_variables
        .variables
        .iter()
        .map(|v| Variable {
            name: v.name.clone(),
            vr: v.value_reference,
            causality: match v.causality {
                Causality2::Parameter => Causality::Parameter,
                Causality2::Input => Causality::Input,
                Causality2::Output => Causality::Output,
                Causality2::Local => Causality::Local,
                _ => Causality::Other,
            },
            kind: match v.elem {
                ScalarVariableElement::Real(_) => Kind::Real,
                ScalarVariableElement::Integer(_) => Kind::Integer,
                _ => Kind::Other,
            },
            scalar: true,
        })
        .collect();
    // A state is the variable a derivative names, by its 1-based index in ModelVariables.
    let all = &md.model_variables.variables;
    let mut states = Vec::new();
    for unknown in &md.model_structure.derivatives.unknowns {
        let der = all.get((unknown.index as usize).wrapping_sub(1)).ok_or("a derivative's index is out of range")?;
        let ScalarVariableElement::Real(real) = &der.elem else {
            return Err(format!("derivative {} is not Real", der.name));
        };
        let state = real.derivative.and_then(|i| all.get((i as usize).wrapping_sub(1)));
        states.push(state.ok_or_else(|| format!("derivative {} names no state", der.name))?.value_reference);
    }
    let interface = |id: &str, serialize: Option<bool>| Interface {
        identifier: id.to_string(),
        can_serialize: serialize.unwrap_or(false),
    };
    Ok(Description {
        version: Version::Fmi2,
        token: md.guid.clone(),
        model_exchange: md.model_exchange.as_ref().map(|i| interface(&i.model_identifier, i.can_serialize_fmu_state)),
        co_simulation: md.co_simulation.as_ref().map(|i| interface(&i.model_identifier, i.can_serialize_fmu_state)),
        variables,
        states,
    })
}

fn from_fmi3(md: &Fmi3ModelDescription) -> Result<Description, String> {
    let mut variables = Vec::new();
    let mut derivative_of = std::collections::HashMap::new();
    for v in &md.model_variables.variables {
        let (abstract_var, kind, scalar): (&dyn AbstractVariableTrait, Kind, bool) = match v {
            Var3::Float64(f) => {
                if let Some(state) = f.derivative() {
                    derivative_of.insert(f.value_reference, state);
                }
                (f, Kind::Real, f.dimensions.is_empty())
            }
            Var3::Int32(i) => (i, Kind::Integer, i.dimensions.is_empty()),
            other => (variable3(other), Kind::Other, true),
        };
        variables.push(Variable {
            name: abstract_var.name().to_string(),
            vr: abstract_var.value_reference(),
            causality: match abstract_var.causality() {
                Causality3::Parameter => Causality::Parameter,
                Causality3::Input => Causality::Input,
                Causality3::Output => Causality::Output,
                Causality3::Local => Causality::Local,
                _ => Causality::Other,
            },
            kind,
            scalar,
        });
    }
    let mut states = Vec::new();
    for unknown in &md.model_structure.unknowns {
        if let VariableDependency::ContinuousStateDerivative(u) = unknown {
            let state = derivative_of.get(&u.value_reference);
            states.push(*state.ok_or_else(|| format!("derivative {} names no state", u.value_reference))?);
        }
    }
    let interface = |id: &str, serialize: Option<bool>| Interface {
        identifier: id.to_string(),
        can_serialize: serialize.unwrap_or(false),
    };
    Ok(Description {
        version: Version::Fmi3,
        token: md.instantiation_token.clone(),
        model_exchange: md.model_exchange.as_ref().map(|i| interface(&i.model_identifier, i.can_serialize_fmu_state)),
        co_simulation: md.co_simulation.as_ref().map(|i| interface(&i.model_identifier, i.can_serialize_fmu_state)),
        variables,
        states,
    })
}

fn variable3(v: &Var3) -> &dyn AbstractVariableTrait {
    match v {
        Var3::Int8(x) => x,
        Var3::UInt8(x) => x,
        Var3::Int16(x) => x,
        Var3::UInt16(x) => x,
        Var3::Int32(x) => x,
        Var3::UInt32(x) => x,
        Var3::Int64(x) => x,
        Var3::UInt64(x) => x,
        Var3::Float32(x) => x,
        Var3::Float64(x) => x,
        Var3::Boolean(x) => x,
        Var3::String(x) => x,
        Var3::Binary(x) => x,
        Var3::Clock(x) => x,
    }
}
