//! Which thesis findings each sweep answers, and how (see [`super::claims`] for the rule).

use super::claims::{
    Claim, Group, Metric, PSNR_MARGIN_DB, Paired, TIME_MARGIN, Verdict, both, run_undertrained, undertrained_if,
};
use super::results::{RunResult, mean};

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
                out.push(undertrained_if(claim(
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
                ), run_undertrained(r).into_iter().collect()));
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
                let groups = [format!("{opt}-const"), format!("{opt}-cosine"), format!("{opt}-sgdr")];
                out.push(g.gated(
                    claim(&format!("Learning-rate schedules change {opt} little (figure {fig})"), measured, verdict),
                    &groups.iter().map(String::as_str).collect::<Vec<_>>(),
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
            out.push(g.better(
                sweep,
                "(Not in the thesis; its §9 names sample statistics as future work.) The color's per-pixel variance \
                 as a further input improves on albedo + normal",
                "annv",
                "ann",
                Metric::Psnr,
            ));
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
                    out.push(g.gated(claim(
                        thesis,
                        format!(
                            "PSNR gain of ann over n: {low_gain:.3} dB at {lo} spp, {:.3} dB at {hi} spp; gain at {lo} \
                             minus gain at {hi}: {p}. Rule: the direction rule, inconclusive unless the gain at {lo} spp \
                             is positive",
                            mean(gh.iter().copied()).unwrap_or(f64::NAN)
                        ),
                        verdict,
                    ), &["ann", "n"]));
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
                "(Not in the thesis: Bako et al. 2017.) Predicting 5×5 kernels that filter the noisy color beats \
                 predicting the color, in the same steps (each run's seconds per epoch are in the report)",
                "kpcn",
                "direct",
                Metric::Psnr,
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
        "init" => vec![g.better(
            sweep,
            "(Not in the thesis: its toolkit could not start from trained weights.) Fine-tuning OIDN's official \
             weights beats training the same network from scratch in the same steps",
            "oidn",
            "scratch",
            Metric::Psnr,
        )],
        _ => Vec::new(),
    }
}
