//! Every progress bar of the command line: the pipeline's [`Observer`] drawn with indicatif, and the bar of
//! a single render. Bars go to standard error and vanish when it is not a terminal; notes are printed above
//! them.

use std::cell::RefCell;
use std::time::{Duration, Instant};

use anyhow::Result;
use hush_pipeline::{Observer, RenderProgress};
use hush_scene::Scene;
use hush_trace::{RenderOutput, RenderSettings, Renderer};
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};

fn style(template: &str) -> ProgressStyle {
    ProgressStyle::with_template(template).expect("valid template").progress_chars("=> ")
}

/// Draws what the pipeline reports: a bar for the task (images of a dataset, steps of a training), below it
/// a bar for each render, and notes above both.
#[derive(Default)]
pub struct Bars {
    multi: MultiProgress,
    task: RefCell<Option<ProgressBar>>,
}

impl Observer for Bars {
    fn note(&self, line: &str) {
        if self.multi.is_hidden() {
            eprintln!("{line}");
        } else {
            let _ = self.multi.println(line);
        }
    }

    fn task(&self, name: &str, unit: &str, total: u64, done: u64) {
        let bar = self.multi.add(ProgressBar::new(total));
        bar.set_style(style(&format!(
            "{{prefix}} [{{bar:30}}] {{pos}}/{{len}} {unit}, {{msg}} elapsed {{elapsed}} eta {{eta}}"
        )));
        bar.set_prefix(name.to_string());
        bar.set_position(done);
        *self.task.borrow_mut() = Some(bar);
    }

    fn progress(&self, done: u64, message: &str) {
        if let Some(bar) = self.task.borrow().as_ref() {
            bar.set_position(done);
            bar.set_message(message.to_string());
        }
    }

    fn task_done(&self) {
        if let Some(bar) = self.task.borrow_mut().take() {
            bar.finish_and_clear();
            self.multi.remove(&bar);
        }
    }

    fn render(&self, label: &str, spp: u32) -> Box<dyn RenderProgress + '_> {
        let bar = self.multi.add(ProgressBar::new(spp as u64));
        bar.set_style(style("{prefix} [{bar:30}] {pos}/{len} spp {msg} eta {eta}"));
        bar.set_prefix(label.to_string());
        Box::new(RenderBar { bar, multi: &self.multi })
    }
}

struct RenderBar<'a> {
    bar: ProgressBar,
    multi: &'a MultiProgress,
}

impl RenderProgress for RenderBar<'_> {
    fn update(&mut self, done: u32, mpaths_per_second: f64) {
        self.bar.set_message(format!("{mpaths_per_second:.2} M paths/s"));
        self.bar.set_position(done as u64);
    }
}

impl Drop for RenderBar<'_> {
    fn drop(&mut self) {
        self.bar.finish_and_clear();
        self.multi.remove(&self.bar);
    }
}

/// Renders with a bar: samples per pixel done, M paths/s and the time left (to the spp asked for, or to the
/// end of `time_limit`, which then bounds the render as in [`Renderer::render_within`]).
pub fn render(
    renderer: &Renderer,
    scene: &Scene,
    settings: &RenderSettings,
    time_limit: Option<Duration>,
    label: &str,
) -> Result<RenderOutput> {
    // With a time limit the bar measures time (in milliseconds), so its ETA is the budget left.
    let (len, template) = match time_limit {
        None => (settings.spp as u64, "{prefix} [{bar:30}] {pos}/{len} spp {msg} eta {eta}"),
        Some(limit) => (limit.as_millis().max(1) as u64, "{prefix} [{bar:30}] {msg} eta {eta}"),
    };
    let bar = ProgressBar::new(len);
    bar.set_style(style(template));
    bar.set_prefix(label.to_string());
    let pixels = scene.film.width as f64 * scene.film.height as f64;
    let start = Instant::now();
    let out = renderer.render_within(scene, settings, time_limit, &mut |done, _| {
        let elapsed = start.elapsed();
        let rate = pixels * done as f64 / elapsed.as_secs_f64().max(1e-9) / 1e6;
        match time_limit {
            None => {
                bar.set_message(format!("{rate:.2} M paths/s"));
                bar.set_position(done as u64);
            }
            Some(_) => {
                bar.set_message(format!("{done} spp {rate:.2} M paths/s"));
                bar.set_position((elapsed.as_millis() as u64).min(len));
            }
        }
    })?;
    bar.finish_and_clear();
    Ok(out)
}
