//! `liblooplab_stage.so`: a stage of your own in C, run by LoopLab's own runner
//! (`looplab_sdk::runtime::stage::user_stage`). The C program implements a `looplab_step` and calls
//! `looplab_run`; everything else (waiting, stamps, faults, the ready and report lines, signals)
//! is the same relay the built-in stages run. `build.rs` writes the header `looplab_stage.h`
//! beside the library.

#![allow(non_camel_case_types)]

use std::ffi::{CStr, CString, c_char, c_int, c_void};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::process::ExitCode;
use std::sync::OnceLock;

use anyhow::{Result, bail};
use looplab_sdk::contract::protocol::{ProcessArgs, stage_env};
use looplab_sdk::contract::role::Role;
use looplab_sdk::model::reference::{Signal, declared_references};
use looplab_sdk::runtime::stage::user_stage::{self, MAX_FROZEN_BYTES, Step, config_number, stage_names};

/// The most bytes a `looplab_freeze` may write (a snapshot's room for a stage's state: 64 KiB).
pub const LOOPLAB_MAX_FROZEN_BYTES: usize = 65536;
const _: () = assert!(LOOPLAB_MAX_FROZEN_BYTES == MAX_FROZEN_BYTES);

/// Computes this loop's output from its input at simulation time `t` (seconds). `in` holds
/// `n_in` numbers (named by `looplab_input_name`), `out` has room for `n_out` (named by
/// `looplab_output_name`; zero at the start of every loop). Returns 0, or non-zero for an
/// error: the stage's incarnation ends with "step returned <code>" and the launch file's
/// restart policy applies.
pub type looplab_step = Option<
    unsafe extern "C" fn(
        user: *mut c_void,
        t: f64,
        r#in: *const f64,
        n_in: usize,
        out: *mut f64,
        n_out: usize,
    ) -> c_int,
>;

/// Writes the state to keep across a restart into `buf` (room for `cap` =
/// `LOOPLAB_MAX_FROZEN_BYTES` bytes) and returns how many bytes it wrote; 0: nothing to keep.
/// Called after every loop.
pub type looplab_freeze = Option<unsafe extern "C" fn(user: *mut c_void, buf: *mut u8, cap: usize) -> usize>;

/// A restarted stage gets its predecessor's frozen `len` bytes before its first step. Returns 0,
/// or non-zero for an error (the incarnation ends).
pub type looplab_thaw = Option<unsafe extern "C" fn(user: *mut c_void, buf: *const u8, len: usize) -> c_int>;

/// Runs the stage the launcher started (the environment says which: sensors, estimator or
/// controller), calling `step` with `user` once per loop. Returns the process's exit code, for
/// `main` to return.
#[unsafe(no_mangle)]
pub extern "C" fn looplab_run(step: looplab_step, user: *mut c_void) -> c_int {
    looplab_run_with_state(step, None, None, user)
}

/// `looplab_run` with state kept across a restart: `freeze` after every loop, `thaw` in a
/// restarted stage before its first step. Either may be NULL.
#[unsafe(no_mangle)]
pub extern "C" fn looplab_run_with_state(
    step: looplab_step,
    freeze: looplab_freeze,
    thaw: looplab_thaw,
    user: *mut c_void,
) -> c_int {
    let Some(step) = step else {
        eprintln!("error: looplab_run was given no step function");
        return 2;
    };
    let user_step = CStep { step, freeze, thaw, user };
    // A panic must not unwind into C; Rust's own exit code for one is 101.
    let code = catch_unwind(AssertUnwindSafe(|| user_stage::run_step(move |_| Ok(Box::new(user_step)))));
    code.map_or(101, exit_status)
}

/// The number an `ExitCode` stands for (the runner's are 0 to 255).
fn exit_status(code: ExitCode) -> c_int {
    (0..=u8::MAX).find(|&c| ExitCode::from(c) == code).map_or(1, c_int::from)
}

/// The user's C functions as a [`Step`].
struct CStep {
    step: unsafe extern "C" fn(*mut c_void, f64, *const f64, usize, *mut f64, usize) -> c_int,
    freeze: looplab_freeze,
    thaw: looplab_thaw,
    user: *mut c_void,
}

impl Step for CStep {
    fn step(&mut self, t: f64, input: &[f64], output: &mut [f64]) -> Result<()> {
        // SAFETY: the C side gets valid buffers of the lengths it is told.
        let code = unsafe { (self.step)(self.user, t, input.as_ptr(), input.len(), output.as_mut_ptr(), output.len()) };
        if code != 0 {
            bail!("step returned {code}");
        }
        Ok(())
    }

    fn freeze(&self) -> Result<Option<Vec<u8>>> {
        let Some(freeze) = self.freeze else { return Ok(None) };
        let mut buf = vec![0u8; LOOPLAB_MAX_FROZEN_BYTES];
        // SAFETY: buf has room for the cap it is given.
        let len = unsafe { freeze(self.user, buf.as_mut_ptr(), buf.len()) };
        if len > buf.len() {
            bail!("freeze says it wrote {len} bytes; it has room for {}", buf.len());
        }
        buf.truncate(len);
        Ok((len > 0).then_some(buf))
    }

    fn thaw(&mut self, frozen: &[u8]) -> Result<()> {
        let Some(thaw) = self.thaw else { return Ok(()) };
        // SAFETY: frozen is valid for its length.
        let code = unsafe { thaw(self.user, frozen.as_ptr(), frozen.len()) };
        if code != 0 {
            bail!("thaw returned {code}");
        }
        Ok(())
    }
}

/// What a C program may read before `looplab_run`: the run's resolved launch file and the
/// component names of its role, loaded once from the environment the launcher set.
struct Launch {
    document: toml::Table,
    inputs: Vec<CString>,
    outputs: Vec<CString>,
    /// A declared system's references, and what each tracks.
    references: Vec<Signal>,
    reference_names: Vec<CString>,
}

fn launch() -> Option<&'static Launch> {
    static LAUNCH: OnceLock<Option<Launch>> = OnceLock::new();
    LAUNCH.get_or_init(load_launch).as_ref()
}

/// None outside a run (the variables missing) or if the launch file does not load: it says so
/// on stderr once (looplab_run would say the same).
fn load_launch() -> Option<Launch> {
    let Some((role_name, args)) = ProcessArgs::from_env() else {
        eprintln!(
            "error: this program is a LoopLab stage: start it from a launch file's [stages.<role>] command with \
             `looplab run`, which sets {} and the run's other variables",
            stage_env::ROLE
        );
        return None;
    };
    let config = match looplab_sdk::config::launch::load_run_config(&args.launch) {
        Ok(loaded) => loaded,
        Err(e) => {
            eprintln!("{role_name}: error: {e}");
            return None;
        }
    };
    let (inputs, outputs) = match role_name.parse::<Role>() {
        Ok(role) if Role::STAGES.contains(&role) => stage_names(role, &config),
        _ => (vec![], vec![]),
    };
    let references = match declared_references(&config) {
        Ok(references) => references,
        Err(e) => {
            eprintln!("{role_name}: error: {e}");
            return None;
        }
    };
    let c_strings = |names: Vec<String>| names.into_iter().filter_map(|n| CString::new(n).ok()).collect();
    Some(Launch {
        document: config.document,
        inputs: c_strings(inputs),
        outputs: c_strings(outputs),
        reference_names: c_strings(references.iter().map(|r| r.track.clone()).collect()),
        references: references.into_iter().map(|r| r.signal).collect(),
    })
}

/// Reads the number at dotted `key` of the run's resolved launch file (`"controller.gains.1"`:
/// tables by name, arrays by index) into `*value`. Returns 0; 1 if the key is missing or not a
/// number; 2 if there is no launch file (the program was not started by `looplab run`). Works
/// before `looplab_run`.
///
/// # Safety
/// `key` is a NUL-terminated string and `value` points to a double (a NULL one returns 1).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn looplab_config_f64(key: *const c_char, value: *mut f64) -> c_int {
    let Some(launch) = launch() else { return 2 };
    if key.is_null() || value.is_null() {
        return 1;
    }
    // SAFETY: the caller passes a NUL-terminated string.
    let Ok(key) = unsafe { CStr::from_ptr(key) }.to_str() else { return 1 };
    match config_number(&launch.document, key) {
        Some(number) => {
            // SAFETY: the caller passes a pointer to a double.
            unsafe { *value = number };
            0
        }
        None => 1,
    }
}

/// Writes each of a declared system's references (`[reference]`) at simulation time `t` (s)
/// into `out` (room for `n`), in the order of `looplab_reference_name`, and returns how many the
/// run has (0 outside a run or without a reference); the first `n` of them are written.
///
/// # Safety
/// `out` points to `n` doubles (NULL with `n` = 0 asks for the count).
#[unsafe(no_mangle)]
pub unsafe extern "C" fn looplab_reference(t: f64, out: *mut f64, n: usize) -> usize {
    let Some(launch) = launch() else { return 0 };
    if !out.is_null() {
        for (i, signal) in launch.references.iter().take(n).enumerate() {
            // SAFETY: the caller passes room for n doubles.
            unsafe { *out.add(i) = signal.at(t) };
        }
    }
    launch.references.len()
}

/// What reference `i` tracks (`"state.position"`), NULL past the end; as `looplab_input_name`.
#[unsafe(no_mangle)]
pub extern "C" fn looplab_reference_name(i: usize) -> *const c_char {
    name_at(launch().map(|l| &l.reference_names), i)
}

/// How many numbers the step's input has (0 outside a run).
#[unsafe(no_mangle)]
pub extern "C" fn looplab_input_count() -> usize {
    launch().map_or(0, |l| l.inputs.len())
}

/// How many numbers the step's output has (0 outside a run).
#[unsafe(no_mangle)]
pub extern "C" fn looplab_output_count() -> usize {
    launch().map_or(0, |l| l.outputs.len())
}

/// The name of input number `i` (`"theta"`, `"encoder.valid"`...), NULL past the end. The
/// string lives as long as the process.
#[unsafe(no_mangle)]
pub extern "C" fn looplab_input_name(i: usize) -> *const c_char {
    name_at(launch().map(|l| &l.inputs), i)
}

/// The name of output number `i`, NULL past the end; as `looplab_input_name`.
#[unsafe(no_mangle)]
pub extern "C" fn looplab_output_name(i: usize) -> *const c_char {
    name_at(launch().map(|l| &l.outputs), i)
}

fn name_at(names: Option<&Vec<CString>>, i: usize) -> *const c_char {
    names.and_then(|n| n.get(i)).map_or(std::ptr::null(), |name| name.as_ptr())
}
