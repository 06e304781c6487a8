//! A system declared in the launch file (helper A writes this module; on the FMU branch it holds
//! only the FMU plant model until the branches merge).

pub mod fmu;
