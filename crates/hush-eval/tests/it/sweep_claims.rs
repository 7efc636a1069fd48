//! The thesis's claims decided from runs (moved with the claims from xtask).

use std::path::Path;

use hush_eval::sweep::claims::{Claim, Paired, Verdict, claims};
use hush_eval::sweep::results::{EvalRow, RunResult};

use crate::sweep::epoch;

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

/// Evaluation rows of `method`: PSNR per (spp, value), two rows per view.
fn rows(method: &str, psnr: &[(u64, f64)]) -> Vec<EvalRow> {
    psnr.iter()
        .enumerate()
        .map(|(i, &(spp, p))| EvalRow {
            view: format!("v{}", i / 2),
            method: method.into(),
            spp,
            psnr: Some(p),
            ..Default::default()
        })
        .collect()
}

fn result(group: &str, psnr: &[(u64, f64)], epochs: &[(usize, f64, f64)]) -> RunResult {
    let run = crate::sweep::run("s", group, Path::new("s"));
    let eval = rows("train/model", psnr);
    let epochs = epochs.iter().map(|&(e, tr, te)| epoch(e, tr, Some(te), e as f64)).collect();
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
    assert_eq!(claims[2].verdict, Verdict::NotMeasured, "the variance needs `annv`");
    assert_eq!(claims[3].verdict, Verdict::Reproduced, "{:?}", claims[3]);
    assert!(claims[3].measured.contains("at 4 spp"), "{}", claims[3].measured);
    // Features that hurt everywhere, less so at low spp: nothing to matter most.
    let worse = result("ann", &[(4, 19.0), (64, 29.0), (4, 20.0), (64, 30.0), (4, 18.0), (64, 28.5)], &[]);
    let n = result("n", &[(4, 20.0), (64, 31.0), (4, 21.0), (64, 32.0), (4, 19.0), (64, 30.5)], &[]);
    assert_eq!(hush_eval::sweep::claims::claims("features", &[n, worse])[3].verdict, Verdict::Inconclusive);
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

/// The precondition: a quality claim none of whose models beats the noisy input at every test spp is
/// inconclusive (undertrained) and names the runs and spp; where one model falls short and the other does
/// not, the verdict stands and names the one that fell short; with noisy rows below both models it is
/// decided as before; a timing claim is decided whatever the models learned.
#[test]
fn claims_between_models_below_the_noisy_input_are_undertrained() {
    let with_noisy = |mut r: RunResult, noisy: &[(u64, f64)]| {
        r.eval.extend(rows("noisy", noisy));
        r
    };
    // Two logged epochs, one second each: what the timing claim reads.
    let epochs = |_: f64| vec![(1, 1.0, 1.0), (2, 1.0, 1.0)];
    let psnr_n = [(4, 20.0), (64, 30.0), (4, 21.0), (64, 31.0), (4, 19.0), (64, 29.5)];
    let psnr_ann = [(4, 23.0), (64, 30.5), (4, 24.2), (64, 31.4), (4, 21.9), (64, 30.1)];
    // The noisy input: 15 dB at 4 spp, and at 64 spp 30.3 dB: above `n` (30.17 on average), below `ann`
    // (30.67): one working model against one that does not work, a comparison that is decided.
    let noisy = [(4, 15.0), (64, 30.3), (4, 15.0), (64, 30.3), (4, 15.0), (64, 30.3)];
    let n = with_noisy(result("n", &psnr_n, &epochs(1.0)), &noisy);
    let ann = with_noisy(result("ann", &psnr_ann, &epochs(1.0)), &noisy);
    let c = claims("features", &[n, ann.clone()]);
    assert_eq!(c[0].verdict, Verdict::Reproduced, "{:?}", c[0]);
    assert!(
        c[0].measured.contains(
            "Below the noisy input (not every model compared): `n` (seed 0) at 64 spp: 30.17 dB against the noisy 30.30"
        ),
        "{}",
        c[0].measured
    );
    // At 64 spp the noisy input's 31.0 dB is above both: no model compared is worth using.
    let high = [(4, 15.0), (64, 31.0), (4, 15.0), (64, 31.0), (4, 15.0), (64, 31.0)];
    let c = claims(
        "features",
        &[with_noisy(result("n", &psnr_n, &[]), &high), with_noisy(result("ann", &psnr_ann, &[]), &high)],
    );
    assert_eq!(c[0].verdict, Verdict::Undertrained, "{:?}", c[0]);
    assert!(c[0].measured.contains("`n` (seed 0) at 64 spp: 30.17 dB against the noisy 31.00"), "{}", c[0].measured);
    assert!(c[0].measured.contains("`ann` (seed 0) at 64 spp: 30.67 dB against the noisy 31.00"), "{}", c[0].measured);
    assert_eq!(c[3].verdict, Verdict::Undertrained, "features at low spp compare the same two: {:?}", c[3]);
    assert_eq!(c[0].verdict.to_string(), "inconclusive: undertrained");
    // Below both models at every spp: decided by the rule, as without noisy rows.
    let low = [(4, 15.0), (64, 25.0), (4, 15.0), (64, 25.0), (4, 15.0), (64, 25.0)];
    let c = claims(
        "features",
        &[with_noisy(result("n", &psnr_n, &[]), &low), with_noisy(result("ann", &psnr_ann, &[]), &low)],
    );
    assert_eq!(c[0].verdict, Verdict::Reproduced, "{:?}", c[0]);
    // A timing claim does not depend on the models' quality.
    let dsnn = with_noisy(result("dsnn", &psnr_ann, &epochs(1.0)), &noisy);
    let n = with_noisy(result("n", &psnr_n, &epochs(1.0)), &noisy);
    let c = claims("features", &[n, ann, dsnn]);
    let timing = c.iter().find(|c| c.thesis.contains("train about equally fast")).expect("the timing claim");
    assert_ne!(timing.verdict, Verdict::Undertrained, "{timing:?}");
}
