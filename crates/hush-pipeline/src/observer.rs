//! How the pipeline reports progress: an [`Observer`] hears about long tasks, renders and notes (warnings and
//! what was done). The command line draws progress bars from it; a library user may log, or ignore it
//! ([`Quiet`]). Nothing in the pipeline prints.

/// Hears what a pipeline stage is doing. Every method has an empty default.
pub trait Observer {
    /// A line for the user: a warning (starting with `warning:`) or what was done.
    fn note(&self, line: &str) {
        let _ = line;
    }

    /// A long task starts: `total` units (`unit`: "images", "steps"), of which `done` are already done.
    fn task(&self, name: &str, unit: &str, total: u64, done: u64) {
        let _ = (name, unit, total, done);
    }

    /// The task has `done` units done; `message` says where it is.
    fn progress(&self, done: u64, message: &str) {
        let _ = (done, message);
    }

    /// The task has ended (successfully or not).
    fn task_done(&self) {}

    /// A render of `spp` samples per pixel starts: the returned handle hears its progress, and dropping it
    /// ends the render's display.
    fn render(&self, label: &str, spp: u32) -> Box<dyn RenderProgress + '_> {
        let _ = (label, spp);
        Box::new(())
    }
}

/// The progress of one render.
pub trait RenderProgress {
    /// `done` samples per pixel of the render are finished, at `mpaths_per_second`.
    fn update(&mut self, done: u32, mpaths_per_second: f64);
}

impl RenderProgress for () {
    fn update(&mut self, _: u32, _: f64) {}
}

/// An observer that ignores everything.
#[derive(Clone, Copy, Debug, Default)]
pub struct Quiet;

impl Observer for Quiet {}

/// An observer that writes the notes to standard error and ignores progress (for scripts and logs).
#[derive(Clone, Copy, Debug, Default)]
pub struct Notes;

impl Observer for Notes {
    fn note(&self, line: &str) {
        eprintln!("{line}");
    }
}
