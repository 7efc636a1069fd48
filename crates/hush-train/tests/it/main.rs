//! hush-train's integration tests: tiny synthetic denoising problems, seconds in total.

use std::ops::ControlFlow;

use candle_core::Device;
use hush_dataset::Image;
use hush_net::transfer::{Transfer, autoexposure};
use hush_net::{Features, UNetConfig, UNetKind, load_model, prepare_color};
use hush_train::{Resume, TrainConfig, TrainError, TrainSample, Trained, train};

/// Deterministic noise in [-1, 1).
fn noise(i: usize, seed: u64) -> f32 {
    let mut s = (i as u64 ^ seed.rotate_left(32)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    s ^= s >> 31;
    s = s.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    s ^= s >> 29;
    (s >> 40) as f32 / (1u64 << 23) as f32 - 1.0
}

/// `n` samples of 32×32: smooth colored targets, inputs = target + strong noise, color only.
fn synthetic(n: usize) -> Vec<TrainSample> {
    (0..n)
        .map(|k| {
            let base = [0.2 + 0.15 * k as f32, 0.5, 0.7 - 0.1 * k as f32];
            let target = Image::from_fn(32, 32, 3, |x, y, c| base[c] + 0.1 * ((x + y) as f32 / 62.0));
            let mut input = target.clone();
            for (i, v) in input.data.iter_mut().enumerate() {
                *v = (*v + 0.25 * noise(i, k as u64)).clamp(0.0, 1.0);
            }
            TrainSample { input, target }
        })
        .collect()
}

fn config(steps: usize) -> TrainConfig {
    let mut cfg = TrainConfig::thesis(Features::default());
    cfg.net = UNetConfig { kind: UNetKind::Unet, in_channels: 3, out_channels: 3, width: 0.25 };
    cfg.steps = steps;
    cfg.batch = 4;
    cfg.crop = 32;
    cfg.checkpoint_every = 0;
    // 10× the thesis' rate so that 30 steps show progress on this toy problem.
    cfg.lr = 1e-3;
    cfg.seed = 11;
    cfg
}

fn run(cfg: &TrainConfig, samples: &[TrainSample]) -> hush_train::Result<Trained> {
    train(cfg, samples, &Device::Cpu, None, |_| ControlFlow::Continue(()))
}

fn losses(t: &Trained) -> Vec<f64> {
    t.log.iter().map(|r| r.loss).collect()
}

#[test]
fn loss_goes_down_on_a_toy_denoising_problem() {
    let samples = synthetic(4);
    let trained = run(&config(30), &samples).unwrap();
    let l = losses(&trained);
    assert_eq!(l.len(), 30);
    let first: f64 = l[..5].iter().sum::<f64>() / 5.0;
    let last: f64 = l[25..].iter().sum::<f64>() / 5.0;
    assert!(last < 0.5 * first, "loss did not drop enough: first steps {first:.4}, last steps {last:.4}: {l:?}");
    // And it denoises: the trained network's loss is below that of the noisy input itself.
    let nchw = |im: &Image| hush_net::hwc_to_nchw(&im.data, 32, 32, 3, &Device::Cpu).unwrap();
    let identity: f64 = samples
        .iter()
        .map(|s| hush_net::loss::mix(&nchw(&s.input), &nchw(&s.target)).unwrap().to_scalar::<f32>().unwrap() as f64)
        .sum::<f64>()
        / samples.len() as f64;
    assert!(last < 0.5 * identity, "trained loss {last:.4} vs noisy input's {identity:.4}");
    let steps: Vec<usize> = trained.log.iter().map(|r| r.step).collect();
    assert_eq!(steps, (1..=30).collect::<Vec<_>>());
    // 4 samples, batch 4: one epoch per step.
    assert_eq!(trained.log[29].epoch, 30);
    assert!(trained.log.windows(2).all(|w| w[0].seconds <= w[1].seconds));
    assert!(!trained.stopped_early);
}

#[test]
fn same_seed_same_losses() {
    let samples = synthetic(3);
    let cfg = config(6);
    let a = losses(&run(&cfg, &samples).unwrap());
    let b = losses(&run(&cfg, &samples).unwrap());
    assert_eq!(a, b);
    let mut other = cfg.clone();
    other.seed = 12;
    assert_ne!(a, losses(&run(&other, &samples).unwrap()));
}

#[test]
fn non_finite_input_is_a_clear_error() {
    let mut samples = synthetic(2);
    let i = (5 * 32 + 3) * 3 + 2; // x=3, y=5, channel 2
    samples[1].input.data[i] = f32::NAN;
    let err = run(&config(3), &samples).unwrap_err();
    assert!(matches!(err, TrainError::Data(_)), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("sample 1 input") && msg.contains("NaN") && msg.contains("x=3 y=5 channel 2"), "{msg}");
}

/// Finite but absurd inputs overflow inside the network: training stops at step 1 with a message naming
/// the step and the likely causes, and hands back the (initial) weights.
#[test]
fn diverging_loss_stops_with_the_last_good_weights() {
    let mut samples = synthetic(2);
    for v in samples.iter_mut().flat_map(|s| s.input.data.iter_mut()) {
        *v = 3e37;
    }
    let cfg = config(3);
    let err = run(&cfg, &samples).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("step 1") && msg.contains("learning rate"), "{msg}");
    let TrainError::Diverged { step, last_good, .. } = err else { panic!("expected Diverged, got {msg}") };
    assert_eq!(step, 1);
    assert!(last_good.log.is_empty());
    let (_, info) = load_model(&last_good.weights, &Device::Cpu).unwrap();
    assert_eq!(info, cfg.model_info());
}

#[test]
fn checkpoints_are_handed_out_and_loadable() {
    let samples = synthetic(2);
    let mut cfg = config(7);
    cfg.checkpoint_every = 3;
    let mut got = Vec::new();
    let trained = train(&cfg, &samples, &Device::Cpu, None, |r| {
        if let Some(bytes) = r.checkpoint {
            got.push((r.row.step, bytes));
        }
        ControlFlow::Continue(())
    })
    .unwrap();
    assert_eq!(got.iter().map(|(s, _)| *s).collect::<Vec<_>>(), vec![3, 6]);
    for (_, bytes) in &got {
        let (_, info) = load_model(bytes, &Device::Cpu).unwrap();
        assert_eq!(info, cfg.model_info());
    }
    assert_ne!(got[1].1, trained.weights, "the final weights are after step 7, not 6");
}

/// Resuming from step-3 weights continues the same crop sequence: its first loss (computed before any
/// update) equals the uninterrupted run's loss at step 4 exactly.
#[test]
fn resume_continues_the_run() {
    let samples = synthetic(3);
    let full = run(&config(5), &samples).unwrap();
    let first = run(&config(3), &samples).unwrap();
    let resumed = train(&config(5), &samples, &Device::Cpu, Some(Resume { weights: &first.weights, step: 3 }), |_| {
        ControlFlow::Continue(())
    })
    .unwrap();
    assert_eq!(resumed.log.iter().map(|r| r.step).collect::<Vec<_>>(), vec![4, 5]);
    assert_eq!(resumed.log[0].loss, full.log[3].loss);

    let mut wider = config(5);
    wider.net.width = 0.5;
    let err = train(&wider, &samples, &Device::Cpu, Some(Resume { weights: &first.weights, step: 3 }), |_| {
        ControlFlow::Continue(())
    })
    .unwrap_err();
    assert!(err.to_string().contains("cannot resume"), "{err}");
}

#[test]
fn observer_can_stop_training() {
    let samples = synthetic(2);
    let trained = train(&config(10), &samples, &Device::Cpu, None, |r| {
        if r.row.step == 2 { ControlFlow::Break(()) } else { ControlFlow::Continue(()) }
    })
    .unwrap();
    assert_eq!(trained.log.len(), 2);
    assert!(trained.stopped_early);
}

#[test]
fn bad_configurations_and_data_are_refused() {
    let samples = synthetic(2);
    let mut cfg = config(2);
    cfg.crop = 20;
    assert!(run(&cfg, &samples).unwrap_err().to_string().contains("multiple of 16"));
    let mut cfg = config(2);
    cfg.crop = 48;
    assert!(run(&cfg, &samples).unwrap_err().to_string().contains("smaller than the 48x48 crop"));
    let mut cfg = config(2);
    cfg.features = Features::parse("alb").unwrap();
    assert!(run(&cfg, &samples).unwrap_err().to_string().contains("input channels"));
    cfg.net.in_channels = 6;
    assert!(run(&cfg, &samples).unwrap_err().to_string().contains("sample 0: input has 3 channels"));
    let mut cfg = config(2);
    cfg.lr = 0.0;
    assert!(matches!(run(&cfg, &samples), Err(TrainError::Config(_))));
    assert!(run(&config(2), &[]).unwrap_err().to_string().contains("no training samples"));
}

/// OIDN's preprocessing: one exposure, from the reference, for input color and target; aux as prepared
/// by hush-net.
#[test]
fn samples_from_linear_images_share_the_reference_exposure() {
    let reference = Image::from_fn(16, 16, 3, |x, _, c| 2.0 + x as f32 + c as f32);
    let color =
        Image::from_fn(16, 16, 3, |x, y, c| if (x + y) % 2 == 0 { 0.0 } else { 2.0 * (3.0 + x as f32 + c as f32) });
    let normal = Image::from_fn(16, 16, 3, |_, _, c| if c == 2 { 1.0 } else { 0.0 });
    let features = Features::parse("nrm").unwrap();
    let s = TrainSample::from_linear(&features, Transfer::Pu, &color, &[&normal], &reference).unwrap();
    let exposure = autoexposure(&reference.data, 16, 16);
    assert_eq!(s.target.data, prepare_color(&reference.data, exposure, Transfer::Pu));
    assert_eq!(s.input.channels, 6);
    let p = (3 * 16 + 4) * 6; // x=4, y=3: odd, so color = 2 × reference
    assert_eq!(
        &s.input.data[p..p + 3],
        &prepare_color(&color.data[(3 * 16 + 4) * 3..][..3], exposure, Transfer::Pu)[..]
    );
    assert_eq!(&s.input.data[p + 3..p + 6], &[0.5, 0.5, 1.0]);
    let small = Image::from_fn(8, 8, 3, |_, _, _| 1.0);
    let err = TrainSample::from_linear(&features, Transfer::Pu, &color, &[&small], &reference).unwrap_err();
    assert!(err.to_string().contains("nrm is 8x8x3"), "{err}");
}
