//! A stage kind for testing the engine's failure handling, `test.fault`: it writes a
//! small file (and optionally a large one), fails, panics or sleeps as its parameters
//! say. The engine's tests use it directly; the CLI registers it only when the
//! environment sets `AMREPRO_TEST_KINDS=1`, so its fault tests can kill, collide and
//! fill disks with a real process.

use std::io::Write;

use crate::error::StageError;
use crate::params::{ParamDefault, ParamSpec, ParamType};
use crate::stage::{Arity, StageContext, StageKind};

/// The environment variable that makes the CLI register [`FaultKind`].
pub const ENV_VAR: &str = "AMREPRO_TEST_KINDS";

/// `test.fault`: see the module documentation.
pub struct FaultKind;

const PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "action",
        ty: ParamType::Choice(&["write", "fail", "panic"]),
        default: ParamDefault::Str("write"),
        doc: "write `value.txt`; or fail with an error; or panic (after the sleep)",
    },
    ParamSpec { name: "text", ty: ParamType::Text, default: ParamDefault::Str(""), doc: "first line of `value.txt`" },
    ParamSpec {
        name: "pad_bytes",
        ty: ParamType::Int { min: 0, max: 1 << 32 },
        default: ParamDefault::Int(0),
        doc: "also write `pad.bin` of this many bytes (to fill a disk)",
    },
    ParamSpec {
        name: "sleep_ms",
        ty: ParamType::Int { min: 0, max: 600_000 },
        default: ParamDefault::Int(0),
        doc: "sleep this long first (to be killed or collided with)",
    },
];

impl StageKind for FaultKind {
    fn name(&self) -> &'static str {
        "test.fault"
    }
    fn version(&self) -> u32 {
        1
    }
    fn summary(&self) -> &'static str {
        "testing only: writes its text and its inputs' texts, or fails, or panics"
    }
    fn implements(&self) -> &'static str {
        "the engine's failure semantics (ARCHITECTURE.md)"
    }
    fn params(&self) -> &'static [ParamSpec] {
        PARAMS
    }
    fn arity(&self) -> Arity {
        Arity { min: 0, max: 8 }
    }
    fn run(&self, ctx: &mut StageContext) -> Result<(), StageError> {
        std::thread::sleep(std::time::Duration::from_millis(ctx.params.i64("sleep_ms") as u64));
        match ctx.params.str("action") {
            "fail" => return Err(StageError::Params { stage: ctx.stage.clone(), message: "told to fail".into() }),
            "panic" => panic!("test.fault told to panic"),
            _ => {}
        }
        let mut text = format!("{}\n", ctx.params.str("text"));
        for input in &ctx.inputs {
            let path = input.dir.join("value.txt");
            text += &std::fs::read_to_string(&path).map_err(|e| StageError::io(&path, e))?;
        }
        let path = ctx.output_path("value.txt")?;
        std::fs::write(&path, text).map_err(|e| StageError::io(&path, e))?;
        write_padding(ctx, ctx.params.i64("pad_bytes") as u64)
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
