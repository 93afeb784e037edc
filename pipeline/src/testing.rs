//! A stage kind for testing the engine's failure handling, `test.fault`: it writes a
//! small file (and optionally a large one), fails, panics or sleeps as its parameters
//! say. The engine's tests use it directly; the CLI registers it only when the
//! environment sets `AMREPRO_TEST_KINDS=1`, so its fault tests can kill, collide and
//! fill disks with a real process.

use std::io::Write;

use crate::error::StageError;
use crate::stage::{Input, Output, Source, Stage, StageContext, StageInfo};

/// The environment variable that makes the CLI register [`FaultKind`].
pub const ENV_VAR: &str = "AMREPRO_TEST_KINDS";

/// `test.fault`: see the module documentation.
pub struct FaultKind;

crate::choice! {
    /// What a `test.fault` stage does.
    pub enum Action {
        /// Write `value.txt`.
        Write = "write",
        /// Fail with an error.
        Fail = "fail",
        /// Panic (after the sleep).
        Panic = "panic",
    }
}

crate::params! {
    /// The parameters of `test.fault`.
    pub struct FaultParams {
        /// write `value.txt`; or fail with an error; or panic (after the sleep)
        pub action: Action = Action::Write,
        /// first line of `value.txt`
        pub text: String = "",
        /// also write `pad.bin` of this many bytes (to fill a disk)
        pub pad_bytes: u64 [0, 1 << 32] = 0,
        /// sleep this long first (to be killed or collided with)
        pub sleep_ms: u64 [0, 600_000] = 0,
    }
}

/// The inputs of `test.fault`: other faults' folders, whose texts it appends.
const UPSTREAM: Input = Input::many("upstream", 0, &[Source::Stage("test.fault")], "other `test.fault` stages");

impl Stage for FaultKind {
    type Params = FaultParams;
    const INFO: &'static StageInfo = &StageInfo {
        name: "test.fault",
        version: 1,
        summary: "testing only: writes its text and its inputs' texts, or fails, or panics",
        implements: "the engine's failure semantics (ARCHITECTURE.md)",
        inputs: &[UPSTREAM],
        output: Output::Tables,
    };

    fn run(&self, ctx: &mut StageContext, p: &FaultParams) -> Result<(), StageError> {
        std::thread::sleep(std::time::Duration::from_millis(p.sleep_ms));
        match p.action {
            Action::Fail => {
                return Err(StageError::Params { stage: ctx.stage.clone(), message: "told to fail".into() })
            }
            Action::Panic => panic!("test.fault told to panic"),
            Action::Write => {}
        }
        let mut text = format!("{}\n", p.text);
        for input in ctx.inputs_of(&UPSTREAM) {
            let path = input.dir.join("value.txt");
            text += &std::fs::read_to_string(&path).map_err(|e| StageError::io(&path, e))?;
        }
        let path = ctx.output_path("value.txt")?;
        std::fs::write(&path, text).map_err(|e| StageError::io(&path, e))?;
        write_padding(ctx, p.pad_bytes)
    }
}

fn write_padding(ctx: &StageContext, bytes: u64) -> Result<(), StageError> {
    if bytes == 0 {
        return Ok(());
    }
    let path = ctx.output_path("pad.bin")?;
    let mut file = std::fs::File::create(&path).map_err(|e| StageError::io(&path, e))?;
    let block = vec![0x5a_u8; 1 << 16];
    let mut left = bytes;
    while left > 0 {
        let n = left.min(block.len() as u64) as usize;
        file.write_all(&block[..n]).map_err(|e| StageError::io(&path, e))?;
        left -= n as u64;
    }
    file.sync_all().map_err(|e| StageError::io(&path, e))
}
