//! The thesis's findings (chapter 7; `anchors.md` "Findings to reproduce") beside what a sweep
//! measured, each decided by a stated rule.
//!
//! The rule: a comparison of runs A and B on a metric pairs the evaluation rows of the same seed, test
//! view and spp, and takes the differences d_i, signed so that d > 0 is the thesis's direction. With
//! their mean d̄ and standard error SE = sd(d_i)/√n: **reproduced** when d̄ > 2·SE, **refuted** when
//! d̄ < −2·SE, **inconclusive** otherwise or with fewer than 2 pairs. A claim of *no* effect is
//! reproduced when |d̄| + 2·SE is below its margin, refuted when |d̄| − 2·SE is above it. The rows of
//! one view at several spp are not independent, so SE is optimistic; more views and seeds fix that.

use std::fmt;

use super::results::{EvalRow, RunResult, mean};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    Reproduced,
    Refuted,
    Inconclusive,
    /// The runs it needs are missing.
    NotMeasured,
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(match self {
            Verdict::Reproduced => "**reproduced**",
            Verdict::Refuted => "**refuted**",
            Verdict::Inconclusive => "inconclusive",
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
struct Group<'a>(&'a [RunResult]);

impl<'a> Group<'a> {
    fn runs(&self, group: &str) -> Vec<&'a RunResult> {
        self.0.iter().filter(|r| r.run.group() == group && r.done).collect()
    }

    /// Differences "`a` better than `b`" on `metric`, paired by seed, view and spp; `None` when either is
    /// missing. `spp` restricts to one spp.
    fn diffs(&self, a: &str, b: &str, metric: Metric, spp: Option<u64>) -> Option<Vec<f64>> {
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

    fn mean_metric(&self, group: &str, metric: Metric) -> Option<f64> {
        mean(self.runs(group).iter().flat_map(|r| r.model_rows()).filter_map(|r| metric.of(r)))
    }

    fn seconds_per_epoch(&self, group: &str) -> Option<f64> {
        mean(self.runs(group).iter().filter_map(|r| r.seconds_per_epoch()))
    }

    /// Mean seconds to denoise one test image.
    fn denoise_seconds(&self, group: &str) -> Option<f64> {
        mean(self.runs(group).iter().flat_map(|r| r.model_rows()).filter_map(|r| r.denoise_seconds))
    }

    /// The spp present in `group`'s evaluation, ascending.
    fn spps(&self, group: &str) -> Vec<u64> {
        let mut s: Vec<u64> = self.runs(group).iter().flat_map(|r| r.model_rows()).map(|r| r.spp).collect();
        s.sort_unstable();
        s.dedup();
        s
    }

    /// "`a` beats `b` on `metric`" as a claim.
    fn better(&self, sweep: &str, thesis: &str, a: &str, b: &str, metric: Metric) -> Claim {
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
    fn better_both(&self, sweep: &str, thesis: &str, x: (&str, &str, Metric), y: (&str, &str, Metric)) -> Claim {
        let a = self.better(sweep, thesis, x.0, x.1, x.2);
        let b = self.better(sweep, thesis, y.0, y.1, y.2);
        Claim { measured: format!("{}; {}", a.measured, b.measured), verdict: both(a.verdict, b.verdict), ..a }
    }
}

fn both(a: Verdict, b: Verdict) -> Verdict {
    use Verdict::*;
    match (a, b) {
        (NotMeasured, _) | (_, NotMeasured) => NotMeasured,
        (Refuted, _) | (_, Refuted) => Refuted,
        (Reproduced, Reproduced) => Reproduced,
        _ => Inconclusive,
    }
}

/// PSNR margin of "makes little difference" claims: differences below it are not worth a choice.
pub const PSNR_MARGIN_DB: f64 = 0.5;
/// "Only a few percent slower": the thesis's spread of training time over the losses was 5.5%.
pub const TIME_MARGIN: f64 = 0.15;

/// Every claim the sweep `sweep` (by name) can answer from its runs.
pub fn claims(sweep: &str, results: &[RunResult]) -> Vec<Claim> {
    let g = Group(results);
    let claim = |thesis: &str, measured: String, verdict| Claim {
        sweep: sweep.into(),
        thesis: thesis.into(),
        measured,
        verdict,
    };
    match sweep {
        "epochs" => {
            let runs: Vec<&RunResult> = results.iter().filter(|r| r.done).collect();
            let mut out = Vec::new();
            for r in runs {
                let tested: Vec<(usize, f64)> = r.epochs.iter().filter_map(|e| Some((e.epoch, e.test_loss?))).collect();
                let thesis = "The test loss reaches its minimum long before the end and then rises: the model overfits \
                              (§7.1: best at epoch 230 of 1270)";
                let (Some((best_epoch, best)), Some(&(last_epoch, last))) = (r.best(), tested.last()) else {
                    out.push(claim(thesis, format!("{}: no test loss logged", r.run.name), Verdict::NotMeasured));
                    continue;
                };
                // The jitter of the test loss: the median absolute second difference of consecutive evaluations
                // (zero for a straight trend, so a steady fall or rise is not mistaken for noise).
                let mut steps: Vec<f64> = tested.windows(3).map(|w| (w[2].1 - 2.0 * w[1].1 + w[0].1).abs()).collect();
                steps.sort_by(f64::total_cmp);
                let jitter = steps.get(steps.len() / 2).copied().unwrap_or(f64::NAN);
                let rise = last - best;
                let gap = r.last_tested().map(|(_, tr, te)| te - tr).unwrap_or(f64::NAN);
                // How much the test loss still fell over the last fifth of the run.
                let late = tested.iter().find(|(e, _)| *e as f64 >= 0.8 * last_epoch as f64).map_or(last, |t| t.1);
                let still_falling = late - last;
                let verdict = if tested.len() < 3 {
                    Verdict::Inconclusive
                } else if best_epoch == last_epoch {
                    // Flat at its best: converged without overfitting. Still falling: too short to tell.
                    if still_falling <= 2.0 * jitter { Verdict::Refuted } else { Verdict::Inconclusive }
                } else if (best_epoch as f64) < 0.8 * last_epoch as f64 && rise > 2.0 * jitter {
                    Verdict::Reproduced
                } else {
                    Verdict::Inconclusive
                };
                out.push(claim(
                    thesis,
                    format!(
                        "{}: best test loss {best:.4} at epoch {best_epoch} of {last_epoch}; final {last:.4} (rise {rise:+.4}, \
                         fall over the last fifth {still_falling:+.4}, 2× jitter {:.4}); generalization gap at the \
                         end {gap:+.4}. Rule: reproduced if the best epoch is before 80% of the run and the rise exceeds \
                         twice the jitter; refuted if the last epoch is the best and the loss fell less than twice the \
                         jitter over the last fifth (converged, no overfitting); inconclusive while it still falls",
                        r.run.name,
                        2.0 * jitter
                    ),
                    verdict,
                ));
            }
            out
        }
        "loss" => {
            let mut out = vec![
                g.better(sweep, "MAE beats MSE, which leaves splotches (§7.2, figure 7.5)", "mae", "mse", Metric::Ssim),
                g.better(
                    sweep,
                    "SSIM losses shift color (insensitive to a uniform bias): the SSIM-trained model has a larger \
                     linear error than the MAE-trained one (§7.2)",
                    "mae",
                    "ssim",
                    Metric::Mae,
                ),
            ];
            out.push(g.better_both(
                sweep,
                "L_MIX fixes both: structure at least as good as MSE's, color error at least as low as MS-SSIM's (§7.2)",
                ("mix", "mse", Metric::Ssim),
                ("mix", "msssim", Metric::Mae),
            ));
            let (measured, verdict) = match (g.seconds_per_epoch("mae"), g.seconds_per_epoch("msssim")) {
                (Some(a), Some(b)) => {
                    let ratio = b / a;
                    let v = if ratio <= 1.0 + TIME_MARGIN { Verdict::Reproduced } else { Verdict::Refuted };
                    (
                        format!(
                            "s/epoch: mae {a:.2}, msssim {b:.2} (×{ratio:.3}). Rule: reproduced if MS-SSIM costs at \
                             most {:.0}% more than MAE",
                            100.0 * TIME_MARGIN
                        ),
                        v,
                    )
                }
                _ => ("needs runs `mae` and `msssim`".into(), Verdict::NotMeasured),
            };
            out.push(claim(
                "Training time per epoch differs little between losses (table 7.1: MS-SSIM 5.5% slower than MAE)",
                measured,
                verdict,
            ));
            out
        }
        "optimizer" => {
            let mut out =
                vec![g.better(sweep, "Adam clearly beats SGD (figure 7.9)", "adam-const", "sgd-const", Metric::Psnr)];
            for (opt, fig) in [("adam", "7.9"), ("sgd", "7.8")] {
                let mut verdict = Verdict::Reproduced;
                let mut parts = Vec::new();
                for s in ["cosine", "sgdr"] {
                    let (a, b) = (format!("{opt}-const"), format!("{opt}-{s}"));
                    match g.diffs(&a, &b, Metric::Psnr, None) {
                        None => verdict = Verdict::NotMeasured,
                        Some(d) => {
                            let p = Paired::of(&d);
                            verdict = both(verdict, p.within(PSNR_MARGIN_DB));
                            parts.push(format!("{a} − {b}: {p}"));
                        }
                    }
                }
                let measured = if verdict == Verdict::NotMeasured {
                    format!("needs runs `{opt}-const`, `{opt}-cosine`, `{opt}-sgdr`")
                } else {
                    format!(
                        "PSNR (dB) {}. Rule: reproduced if every |d̄| + 2·SE < {PSNR_MARGIN_DB} dB",
                        parts.join("; ")
                    )
                };
                out.push(claim(
                    &format!("Learning-rate schedules change {opt} little (figure {fig})"),
                    measured,
                    verdict,
                ));
            }
            out
        }
        "features" => {
            let mut out = vec![
                g.better(sweep, "Auxiliary features improve the result (figure 7.10)", "ann", "n", Metric::Psnr),
                g.better(
                    sweep,
                    "Diffuse + specular + normal slightly beat albedo + normal (figure 7.11)",
                    "dsnn",
                    "ann",
                    Metric::Psnr,
                ),
            ];
            let spps = g.spps("ann");
            let thesis = "Auxiliary features matter most at low spp (§7.4)";
            match (spps.first(), spps.last()) {
                (Some(&lo), Some(&hi)) if lo != hi => {
                    let gain = |s| g.diffs("ann", "n", Metric::Psnr, Some(s)).unwrap_or_default();
                    let (gl, gh) = (gain(lo), gain(hi));
                    let d: Vec<f64> = gl.iter().zip(&gh).map(|(a, b)| a - b).collect();
                    let p = Paired::of(&d);
                    let low_gain = mean(gl.iter().copied()).unwrap_or(f64::NAN);
                    // Features that do not help at low spp leave nothing to "matter most" there.
                    let verdict = if low_gain > 0.0 { p.direction() } else { Verdict::Inconclusive };
                    out.push(claim(
                        thesis,
                        format!(
                            "PSNR gain of ann over n: {low_gain:.3} dB at {lo} spp, {:.3} dB at {hi} spp; gain at {lo} \
                             minus gain at {hi}: {p}. Rule: the direction rule, inconclusive unless the gain at {lo} spp \
                             is positive",
                            mean(gh.iter().copied()).unwrap_or(f64::NAN)
                        ),
                        verdict,
                    ));
                }
                _ => out.push(claim(thesis, "needs runs `ann`, `n` at two spp or more".into(), Verdict::NotMeasured)),
            }
            let times: Vec<(&str, Option<f64>)> = ["n", "ann", "dsnn"].map(|f| (f, g.seconds_per_epoch(f))).into();
            let thesis = "The feature sets train about equally fast: only the input layer changes (§7.4)";
            match times.iter().map(|t| t.1).collect::<Option<Vec<f64>>>() {
                Some(t) => {
                    let (lo, hi) = t.iter().fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
                    let shown: Vec<String> =
                        times.iter().map(|(f, s)| format!("{f} {:.2}", s.unwrap_or(f64::NAN))).collect();
                    out.push(claim(
                        thesis,
                        format!(
                            "s/epoch: {} (slowest ×{:.3} the fastest). Rule: reproduced if within {:.0}%",
                            shown.join(", "),
                            hi / lo,
                            100.0 * TIME_MARGIN
                        ),
                        if hi <= lo * (1.0 + TIME_MARGIN) { Verdict::Reproduced } else { Verdict::Refuted },
                    ));
                }
                None => out.push(claim(thesis, "needs runs `n`, `ann`, `dsnn`".into(), Verdict::NotMeasured)),
            }
            out
        }
        "architecture" => {
            let mut out = vec![g.better(
                sweep,
                "The U-Net clearly beats the autoencoder without skips (table 7.2: test SSIM loss 0.0076 vs 0.0536)",
                "oidn",
                "dae",
                Metric::Ssim,
            )];
            out.push(g.better_both(
                sweep,
                "Smaller widths (M1 ×0.66, M2 ×0.33) denoise worse than OIDN's (figure 7.15)",
                ("oidn", "m1", Metric::Psnr),
                ("oidn", "m2", Metric::Psnr),
            ));
            let (measured, verdict) =
                match (g.seconds_per_epoch("oidn"), g.seconds_per_epoch("m1"), g.seconds_per_epoch("m2")) {
                    (Some(o), Some(m1), Some(m2)) => (
                        format!(
                            "s/epoch: oidn {o:.2}, m1 {m1:.2}, m2 {m2:.2}. Rule: reproduced if m2 < m1 < oidn, refuted \
                             if a smaller model is slower by more than {:.0}%",
                            100.0 * TIME_MARGIN
                        ),
                        if m2 < m1 && m1 < o {
                            Verdict::Reproduced
                        } else if m1 > o * (1.0 + TIME_MARGIN) || m2 > m1 * (1.0 + TIME_MARGIN) {
                            Verdict::Refuted
                        } else {
                            Verdict::Inconclusive
                        },
                    ),
                    _ => ("needs runs `oidn`, `m1`, `m2`".into(), Verdict::NotMeasured),
                };
            out.push(claim(
                "Smaller capacity trains faster (table 7.3: 0.560, 0.413, 0.321 min/epoch)",
                measured,
                verdict,
            ));
            out.push(g.better(
                sweep,
                "A CNN denoises better than Burger et al.'s patch MLP (§7.5.1, argued, not measured: \"the substantial \
                 benefit of using Convolutional Neural Networks\")",
                "oidn",
                "mlp",
                Metric::Psnr,
            ));
            let thesis = "The patch MLP denoises slowly (§7.5.1: patches, one MLP pass each and the merge \"take much \
                          time\"; Burger et al. about a minute per 512² image)";
            out.push(match (g.denoise_seconds("oidn"), g.denoise_seconds("mlp")) {
                (Some(o), Some(m)) => claim(
                    thesis,
                    format!(
                        "denoise s per image: oidn {o:.3}, mlp {m:.3} (×{:.2}). Rule: reproduced if the MLP is slower \
                         than OIDN's U-Net by more than {:.0}%, refuted if faster by more than that",
                        m / o,
                        100.0 * TIME_MARGIN
                    ),
                    if m > o * (1.0 + TIME_MARGIN) {
                        Verdict::Reproduced
                    } else if m * (1.0 + TIME_MARGIN) < o {
                        Verdict::Refuted
                    } else {
                        Verdict::Inconclusive
                    },
                ),
                _ => claim(thesis, "needs runs `oidn`, `mlp`".into(), Verdict::NotMeasured),
            });
            out
        }
        _ => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::results::{Epoch, EvalRow};
    use crate::sweep::spec::{parse_scales, parse_sweep};
    use std::path::Path;

    #[test]
    fn the_decision_rule() {
        // Mean 1, SE = sd/√n = 0.1/√4 = 0.05: clearly in the thesis's direction.
        let clear = Paired::of(&[0.9, 1.1, 0.9, 1.1]);
        assert!((clear.se - 0.0577).abs() < 1e-3, "{clear:?}");
        assert_eq!(clear.direction(), Verdict::Reproduced);
        assert_eq!(Paired::of(&[-0.9, -1.1, -0.9, -1.1]).direction(), Verdict::Refuted);
        // Mean 0.1 against SE 0.5: noise.
        assert_eq!(Paired::of(&[1.1, -0.9, 0.6, -0.4]).direction(), Verdict::Inconclusive);
        assert_eq!(Paired::of(&[5.0]).direction(), Verdict::Inconclusive);
        assert_eq!(Paired::of(&[]).direction(), Verdict::Inconclusive);
        // No-effect claims against a margin of 0.5.
        assert_eq!(Paired::of(&[0.1, 0.0, 0.1, 0.0]).within(0.5), Verdict::Reproduced);
        assert_eq!(clear.within(0.5), Verdict::Refuted);
        assert_eq!(Paired::of(&[0.5, 0.3, 0.5, 0.3]).within(0.5), Verdict::Inconclusive);
    }

    fn result(group: &str, psnr: &[(u64, f64)], epochs: &[(usize, f64, f64)]) -> RunResult {
        let scales = "[tiny]\nscenes=[\"a\"]\n[small]\nscenes=[\"a\"]\n[thesis]\nscenes=[\"a\"]\n";
        let scale = parse_scales(scales, Path::new("s.toml")).unwrap().remove(0);
        let sweep = format!("[[axis]]\nname = \"x\"\nvariants = [{{ name = \"{group}\" }}]\n");
        let run = parse_sweep("s", &sweep, Path::new("s.toml")).unwrap().runs(&scale).remove(0);
        let eval = psnr
            .iter()
            .enumerate()
            .map(|(i, &(spp, p))| EvalRow {
                view: format!("v{}", i / 2),
                method: "train/model".into(),
                spp,
                psnr: Some(p),
                ssim: None,
                mae: None,
                rel_mse: None,
                render_seconds: None,
                denoise_seconds: None,
                preview: None,
            })
            .collect();
        let epochs = epochs
            .iter()
            .map(|&(epoch, tr, te)| Epoch { epoch, train_loss: tr, test_loss: Some(te), seconds: epoch as f64 })
            .collect();
        RunResult { run, done: true, epochs, eval, pictures: vec![] }
    }

    #[test]
    fn features_matter_most_at_low_spp() {
        // Two views at 4 and 64 spp: features gain ~3 dB at 4 spp and ~0.5 dB at 64.
        let n = result("n", &[(4, 20.0), (64, 30.0), (4, 21.0), (64, 31.0), (4, 19.0), (64, 29.5)], &[]);
        let ann = result("ann", &[(4, 23.0), (64, 30.5), (4, 24.2), (64, 31.4), (4, 21.9), (64, 30.1)], &[]);
        let claims = claims("features", &[n, ann]);
        assert_eq!(claims[0].verdict, Verdict::Reproduced, "{claims:?}");
        assert_eq!(claims[1].verdict, Verdict::NotMeasured);
        assert_eq!(claims[2].verdict, Verdict::Reproduced, "{:?}", claims[2]);
        assert!(claims[2].measured.contains("at 4 spp"), "{}", claims[2].measured);
        // Features that hurt everywhere, less so at low spp: nothing to matter most.
        let worse = result("ann", &[(4, 19.0), (64, 29.0), (4, 20.0), (64, 30.0), (4, 18.0), (64, 28.5)], &[]);
        let n = result("n", &[(4, 20.0), (64, 31.0), (4, 21.0), (64, 32.0), (4, 19.0), (64, 30.5)], &[]);
        assert_eq!(super::claims("features", &[n, worse])[2].verdict, Verdict::Inconclusive);
    }

    /// The patch MLP against OIDN's U-Net: quality by paired PSNR, speed by the mean denoise seconds.
    #[test]
    fn the_patch_mlp_against_the_unet() {
        let timed = |group: &str, psnr: &[(u64, f64)], seconds: f64| {
            let mut r = result(group, psnr, &[]);
            r.eval.iter_mut().for_each(|row| row.denoise_seconds = Some(seconds));
            r
        };
        let oidn = timed("oidn", &[(4, 25.0), (16, 26.0), (64, 24.0)], 0.2);
        let find = |c: &[Claim], what: &str| c.iter().find(|c| c.thesis.contains(what)).cloned().expect(what);
        let c = claims("architecture", &[oidn.clone(), timed("mlp", &[(4, 17.0), (16, 18.5), (64, 16.0)], 0.1)]);
        assert_eq!(find(&c, "CNN denoises better").verdict, Verdict::Reproduced);
        let slow = find(&c, "denoises slowly");
        assert_eq!(slow.verdict, Verdict::Refuted, "{slow:?}");
        assert!(slow.measured.contains("oidn 0.200, mlp 0.100 (×0.50)"), "{}", slow.measured);
        let c = claims("architecture", &[oidn.clone(), timed("mlp", &[(4, 26.0), (16, 27.5), (64, 25.0)], 0.5)]);
        assert_eq!(find(&c, "CNN denoises better").verdict, Verdict::Refuted);
        assert_eq!(find(&c, "denoises slowly").verdict, Verdict::Reproduced);
        let c = claims("architecture", &[oidn, timed("mlp", &[(4, 25.0), (16, 26.5), (64, 23.0)], 0.21)]);
        assert_eq!(find(&c, "CNN denoises better").verdict, Verdict::Inconclusive);
        assert_eq!(find(&c, "denoises slowly").verdict, Verdict::Inconclusive);
        assert_eq!(find(&claims("architecture", &[]), "denoises slowly").verdict, Verdict::NotMeasured);
    }

    #[test]
    fn overfitting_is_read_from_the_test_loss_curve() {
        let turn = [(1, 0.5, 0.5), (2, 0.3, 0.3), (3, 0.2, 0.31), (4, 0.1, 0.36), (5, 0.05, 0.4), (6, 0.04, 0.45)];
        assert_eq!(claims("epochs", &[result("base", &[], &turn)])[0].verdict, Verdict::Reproduced);
        // Still falling at the end: too short to tell.
        let falling = [(1, 0.5, 0.5), (2, 0.4, 0.4), (3, 0.3, 0.3), (4, 0.2, 0.2), (5, 0.1, 0.1)];
        let c = claims("epochs", &[result("base", &[], &falling)]);
        assert_eq!(c[0].verdict, Verdict::Inconclusive);
        assert!(c[0].measured.contains("best test loss 0.1000 at epoch 5 of 5"), "{}", c[0].measured);
        // Flat at its best over the last fifth: converged without overfitting.
        let flat = [(2, 0.5, 0.5), (4, 0.3, 0.3), (6, 0.25, 0.2), (8, 0.2, 0.2), (10, 0.2, 0.2), (12, 0.2, 0.2)];
        let flat: Vec<_> = flat.iter().map(|&(e, tr, te)| (e, tr, te - 1e-4 * e as f64)).collect();
        assert_eq!(claims("epochs", &[result("base", &[], &flat)])[0].verdict, Verdict::Refuted);
    }
}
