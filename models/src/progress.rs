//! Progress of a long computation, told to whoever shows it (the pipeline draws a bar
//! per stage; see `stages::progress`). Work may become known as it goes: a virtual print
//! knows its layers before it knows how many frames the camera will take.

/// Told as a computation's steps become known and get done. Shared across rayon
/// threads, so both calls take `&self`.
pub trait Progress: Sync {
    /// `steps` more steps of work are known.
    fn add(&self, steps: u64);
    /// `steps` of the known steps are done.
    fn done(&self, steps: u64);
}

/// Nobody is watching.
impl Progress for () {
    fn add(&self, _steps: u64) {}
    fn done(&self, _steps: u64) {}
}
