//! The virtual extrusion printer with a nozzle-mounted thermal camera (DESIGN §5.3,
//! paper 003: Chen, Yang, Liu, Duan), writing `thermal-sequence` datasets (DESIGN §4).
//!
//! Code map, one file per step:
//! - [`effects`]: the named, switchable extra effects and their strengths.
//! - [`deposition`]: v_e → E = G(s)·E_cmd (eq. 34) → material on a fine grid by mass conservation.
//! - [`heat`]: the temperature field: Newton cooling plus lateral diffusion (exact Green's function, binned).
//! - [`camera`]: the nozzle-mounted Lepton: mount, distortion, rendering, capture schedule (eq. 28).
pub mod camera;
pub mod deposition;
pub mod effects;
pub mod heat;
