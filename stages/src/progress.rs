//! A stage's progress bar (`StageContext::progress`) as the models' and virtual
//! printers' [`Progress`]: the bar's length grows as the work becomes known, its
//! position as the work is done, and it is cleared when the stage lets it go.

use models::progress::Progress;
use pipeline::StageContext;

/// The bar of the running stage (hidden with `--quiet`, off a terminal, or in a work
/// unit of a spread-out run, whose bar is over the units). Until the first work is
/// known it says the work is being counted.
pub struct StageProgress(indicatif::ProgressBar);

impl StageProgress {
    /// A bar with no work known yet.
    pub fn new(ctx: &StageContext) -> Self {
        Self(ctx.progress(0))
    }

    /// A bar over `steps` steps known from the start.
    pub fn with_steps(ctx: &StageContext, steps: u64) -> Self {
        let progress = Self::new(ctx);
        progress.add(steps);
        progress
    }
}

impl Progress for StageProgress {
    fn add(&self, steps: u64) {
        if self.0.length() == Some(0) && steps > 0 {
            self.0.set_style(pipeline::stage::bar_style());
        }
        self.0.inc_length(steps);
    }
    fn done(&self, steps: u64) {
        self.0.inc(steps);
    }
}

impl Drop for StageProgress {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}
