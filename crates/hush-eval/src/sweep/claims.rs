//! The thesis's findings (chapter 7; `anchors.md` "Findings to reproduce") beside what a sweep
//! measured, each decided by a stated rule.
//!
//! The rule: a comparison of runs A and B on a metric pairs the evaluation rows of the same seed, test
//! view and spp, and takes the differences d_i, signed so that d > 0 is the thesis's direction. With
//! their mean d̄ and standard error SE = sd(d_i)/√n: **reproduced** when d̄ > 2·SE, **refuted** when
//! d̄ < −2·SE, **inconclusive** otherwise or with fewer than 2 pairs. A claim of *no* effect is
//! reproduced when |d̄| + 2·SE is below its margin, refuted when |d̄| − 2·SE is above it. The rows of
//! one view at several spp are not independent, so SE is optimistic; more views and seeds fix that.
//!
//! **Precondition.** A verdict between models that all make the image worse says little about the thesis. A
//! model group is worth using where each of its runs beats the noisy input at every test spp (its mean PSNR
//! over the test views above the noisy input's, spp by spp). A quality claim none of whose compared groups is
//! worth using is **inconclusive: undertrained**, never reproduced or refuted; where only some fall short, the
//! verdict stands (a working denoiser against one that does not work is a comparison the thesis makes) and
//! the claim names the runs that fell short and where. A claim about one model needs that model to be worth
//! using. Claims about training or denoising time do not depend on what the model learned and keep their
//! rule.

use std::fmt;

pub use super::findings::claims;
use super::results::{EvalRow, RunResult, mean};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    Reproduced,
    Refuted,
    Inconclusive,
    /// A model it compares does not beat the noisy input at every test spp (the module's precondition).
    Undertrained,
    /// The runs it needs are missing.
    NotMeasured,
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(match self {
            Verdict::Reproduced => "**reproduced**",
            Verdict::Refuted => "**refuted**",
            Verdict::Inconclusive => "inconclusive",
            Verdict::Undertrained => "inconclusive: undertrained",
            Verdict::NotMeasured => "not measured",
        })
    }
}

/// Paired differences: count, mean and standard error of the mean.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Paired {
    pub n: usize,
    pub mean: f64,
    pub se: f64,
}

impl Paired {
    pub fn of(d: &[f64]) -> Paired {
        let n = d.len();
        let m = d.iter().sum::<f64>() / n.max(1) as f64;
        let var = if n > 1 { d.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1) as f64 } else { f64::NAN };
        Paired { n, mean: m, se: (var / n as f64).sqrt() }
    }

    /// The thesis's direction (d > 0) against the spread.
    pub fn direction(&self) -> Verdict {
        if self.n < 2 || !self.se.is_finite() {
            Verdict::Inconclusive
        } else if self.mean > 2.0 * self.se {
            Verdict::Reproduced
        } else if self.mean < -2.0 * self.se {
            Verdict::Refuted
        } else {
            Verdict::Inconclusive
        }
    }

    /// "No effect larger than `margin`".
    pub fn within(&self, margin: f64) -> Verdict {
        if self.n < 2 || !self.se.is_finite() {
            Verdict::Inconclusive
        } else if self.mean.abs() + 2.0 * self.se < margin {
            Verdict::Reproduced
        } else if self.mean.abs() - 2.0 * self.se > margin {
            Verdict::Refuted
        } else {
            Verdict::Inconclusive
        }
    }
}

impl fmt::Display for Paired {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "d̄ = {:+.4} ± {:.4} (2·SE, n = {})", self.mean, 2.0 * self.se, self.n)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Metric {
    Psnr,
    Ssim,
    Mae,
}

impl Metric {
    fn of(self, r: &EvalRow) -> Option<f64> {
        match self {
            Metric::Psnr => r.psnr,
            Metric::Ssim => r.ssim,
            Metric::Mae => r.mae,
        }
    }
    fn higher_is_better(self) -> bool {
        !matches!(self, Metric::Mae)
    }
    fn name(self) -> &'static str {
        match self {
            Metric::Psnr => "PSNR (dB)",
            Metric::Ssim => "SSIM",
            Metric::Mae => "MAE",
        }
    }
}

/// One thesis finding and what the sweep says about it.
#[derive(Clone, Debug)]
pub struct Claim {
    pub sweep: String,
    pub thesis: String,
    pub measured: String,
    pub verdict: Verdict,
}

/// The runs of a sweep, found by their name without the seed.
pub(super) struct Group<'a>(pub(super) &'a [RunResult]);

impl<'a> Group<'a> {
    pub(super) fn runs(&self, group: &str) -> Vec<&'a RunResult> {
        self.0.iter().filter(|r| r.run.group == group && r.done).collect()
    }

    /// Differences "`a` better than `b`" on `metric`, paired by seed, view and spp; `None` when either is
    /// missing. `spp` restricts to one spp.
    pub(super) fn diffs(&self, a: &str, b: &str, metric: Metric, spp: Option<u64>) -> Option<Vec<f64>> {
        let (ra, rb) = (self.runs(a), self.runs(b));
        if ra.is_empty() || rb.is_empty() {
            return None;
        }
        let mut d = Vec::new();
        for x in &ra {
            let Some(y) = rb.iter().find(|y| y.run.seed == x.run.seed) else { continue };
            for row in x.model_rows() {
                if spp.is_some_and(|s| s != row.spp) {
                    continue;
                }
                let other = y.model_rows().into_iter().find(|o| o.view == row.view && o.spp == row.spp);
                if let (Some(p), Some(q)) = (metric.of(row), other.and_then(|o| metric.of(o))) {
                    d.push(if metric.higher_is_better() { p - q } else { q - p });
                }
            }
        }
        Some(d)
    }

    pub(super) fn mean_metric(&self, group: &str, metric: Metric) -> Option<f64> {
        mean(self.runs(group).iter().flat_map(|r| r.model_rows()).filter_map(|r| metric.of(r)))
    }

    pub(super) fn seconds_per_epoch(&self, group: &str) -> Option<f64> {
        mean(self.runs(group).iter().filter_map(|r| r.seconds_per_epoch()))
    }

    /// Mean seconds to denoise one test image.
    pub(super) fn denoise_seconds(&self, group: &str) -> Option<f64> {
        mean(self.runs(group).iter().flat_map(|r| r.model_rows()).filter_map(|r| r.denoise_seconds))
    }

    /// The spp present in `group`'s evaluation, ascending.
    pub(super) fn spps(&self, group: &str) -> Vec<u64> {
        let mut s: Vec<u64> = self.runs(group).iter().flat_map(|r| r.model_rows()).map(|r| r.spp).collect();
        s.sort_unstable();
        s.dedup();
        s
    }

    /// Where a run of `group` does not beat the noisy input (the module's precondition): the first
    /// such run and spp (see [`run_undertrained`]); `None` when every run beats it at every spp.
    pub(super) fn undertrained(&self, group: &str) -> Option<String> {
        self.runs(group).into_iter().find_map(run_undertrained)
    }

    /// `claim` under the precondition: inconclusive (undertrained) when no group of `groups` beats the noisy
    /// input at every spp with each of its runs; either way it names the runs that fall short.
    pub(super) fn gated(&self, mut claim: Claim, groups: &[&str]) -> Claim {
        let short: Vec<String> = groups.iter().filter_map(|g| self.undertrained(g)).collect();
        if short.len() < groups.len() {
            if !short.is_empty() && claim.verdict != Verdict::NotMeasured {
                claim.measured = format!(
                    "{}. Below the noisy input (not every model compared): {}",
                    claim.measured,
                    short.join("; ")
                );
            }
            return claim;
        }
        undertrained_if(claim, short)
    }

    /// "`a` beats `b` on `metric`" as a claim, under the precondition.
    pub(super) fn better(&self, sweep: &str, thesis: &str, a: &str, b: &str, metric: Metric) -> Claim {
        self.gated(self.better_ungated(sweep, thesis, a, b, metric), &[a, b])
    }

    /// [`Self::better`] without the precondition.
    fn better_ungated(&self, sweep: &str, thesis: &str, a: &str, b: &str, metric: Metric) -> Claim {
        let (measured, verdict) = match self.diffs(a, b, metric, None) {
            None => (format!("needs runs `{a}` and `{b}`"), Verdict::NotMeasured),
            Some(d) => {
                let p = Paired::of(&d);
                let means = match (self.mean_metric(a, metric), self.mean_metric(b, metric)) {
                    (Some(x), Some(y)) => format!("{}: {a} {x:.4}, {b} {y:.4}; ", metric.name()),
                    _ => String::new(),
                };
                (format!("{means}{a} better by {p}"), p.direction())
            }
        };
        Claim { sweep: sweep.into(), thesis: thesis.into(), measured, verdict }
    }

    /// Two comparisons that must both hold.
    pub(super) fn better_both(
        &self,
        sweep: &str,
        thesis: &str,
        x: (&str, &str, Metric),
        y: (&str, &str, Metric),
    ) -> Claim {
        // Each comparison under the precondition on its own.
        let a = self.better(sweep, thesis, x.0, x.1, x.2);
        let b = self.better(sweep, thesis, y.0, y.1, y.2);
        Claim { measured: format!("{}; {}", a.measured, b.measured), verdict: both(a.verdict, b.verdict), ..a }
    }
}

/// Where one run does not beat the noisy input: the first spp (ascending) at which its model's mean PSNR over
/// the test views is not above the noisy input's on the same views, as `` `n` (seed 0) at 64 spp: 28.41 dB
/// against the noisy 32.60 ``.
pub(super) fn run_undertrained(r: &RunResult) -> Option<String> {
    let noisy = r.noisy_rows();
    let mut spps: Vec<u64> = r.model_rows().iter().map(|m| m.spp).collect();
    spps.sort_unstable();
    spps.dedup();
    spps.into_iter().find_map(|spp| {
        let pairs: Vec<(f64, f64)> = r
            .model_rows()
            .into_iter()
            .filter(|m| m.spp == spp)
            .filter_map(|m| {
                let n = noisy.iter().find(|n| n.view == m.view && n.spp == spp)?;
                Some((m.psnr?, n.psnr?))
            })
            .collect();
        let (model, input) = (mean(pairs.iter().map(|p| p.0))?, mean(pairs.iter().map(|p| p.1))?);
        (model <= input).then(|| {
            format!("`{}` (seed {}) at {spp} spp: {model:.2} dB against the noisy {input:.2}", r.run.group, r.run.seed)
        })
    })
}

/// `claim` made inconclusive (undertrained) when `short` names runs below the noisy input; a claim not
/// measured stays so.
pub(super) fn undertrained_if(mut claim: Claim, short: Vec<String>) -> Claim {
    if !short.is_empty() && claim.verdict != Verdict::NotMeasured {
        claim.measured = format!("{}. Below the noisy input: {}", claim.measured, short.join("; "));
        claim.verdict = Verdict::Undertrained;
    }
    claim
}

pub(super) fn both(a: Verdict, b: Verdict) -> Verdict {
    use Verdict::*;
    match (a, b) {
        (NotMeasured, _) | (_, NotMeasured) => NotMeasured,
        (Undertrained, _) | (_, Undertrained) => Undertrained,
        (Refuted, _) | (_, Refuted) => Refuted,
        (Reproduced, Reproduced) => Reproduced,
        _ => Inconclusive,
    }
}

/// PSNR margin of "makes little difference" claims: differences below it are not worth a choice.
pub const PSNR_MARGIN_DB: f64 = 0.5;
/// "Only a few percent slower": the thesis's spread of training time over the losses was 5.5%.
pub const TIME_MARGIN: f64 = 0.15;
