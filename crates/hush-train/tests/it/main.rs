//! hush-train's integration tests: tiny synthetic denoising problems, seconds in total.

mod cache;
mod optim;
mod schedule;

use std::ops::ControlFlow;

use candle_core::Device;
use hush_dataset::Image;
use hush_net::transfer::{Transfer, autoexposure};
use hush_net::{Activation, InputFeatures, PatchMlpConfig, UNetConfig, UNetKind, load_model, prepare_color};
use hush_train::{
    Augment, EpochRow, OptimizerConfig, Schedule, Start, TrainConfig, TrainError, TrainSample, Trained, plot_losses,
    read_train_state, train,
};

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
    let mut cfg = TrainConfig::thesis(InputFeatures::default());
    cfg.net = UNetConfig::new(UNetKind::Unet, 3, 0.25).into();
    cfg.steps = steps;
    cfg.batch = 4;
    cfg.crop = 32;
    cfg.eval_every = 0;
    // 10× the thesis' rate so that 30 steps show progress on this toy problem.
    cfg.lr = 1e-3;
    cfg.seed = 11;
    cfg
}

fn run(cfg: &TrainConfig, samples: &[TrainSample]) -> hush_train::Result<Trained> {
    train(cfg, samples, &[], &Device::Cpu, Start::Fresh, |_| ControlFlow::Continue(()))
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

/// With the loss measured through the evaluation's tonemap, training runs the same loop and learns; a
/// configuration written before loss spaces existed reads as the transfer space, and the default is not
/// written, so such runs' config.json stay byte for byte what they were.
#[test]
fn the_tonemapped_loss_space_trains_and_old_configurations_read_as_transfer() {
    let samples = synthetic(4);
    let mut cfg = config(30);
    cfg.loss_space = hush_net::LossSpace::Tonemapped;
    let l = losses(&run(&cfg, &samples).unwrap());
    let first: f64 = l[..5].iter().sum::<f64>() / 5.0;
    let last: f64 = l[25..].iter().sum::<f64>() / 5.0;
    assert!(last < 0.5 * first, "loss did not drop enough: first steps {first:.4}, last steps {last:.4}: {l:?}");
    let plain = serde_json::to_value(config(30)).unwrap();
    assert!(plain.get("loss_space").is_none(), "the default loss space is written: {plain}");
    assert_eq!(serde_json::from_value::<TrainConfig>(plain).unwrap().loss_space, hush_net::LossSpace::Transfer);
    let written = serde_json::to_value(&cfg).unwrap();
    assert_eq!(written["loss_space"], "tonemapped");
}

/// The colour-mean term trains in the same loop and is part of what the run minimizes (a step's loss includes
/// it, so the same weights and crops score higher with it than without); not written when 0, so earlier runs'
/// config.json read and write unchanged.
#[test]
fn the_color_mean_term_is_part_of_the_objective() {
    let samples = synthetic(4);
    let plain_cfg = config(20);
    let mut cfg = config(20);
    cfg.color_mean = 5.0;
    let with = run(&cfg, &samples).unwrap();
    let without = run(&plain_cfg, &samples).unwrap();
    assert!(with.log.iter().all(|r| r.loss.is_finite()));
    // Step 1 starts from the same weights and crops: the first loss differs by the term alone, which is > 0
    // for an untrained network.
    assert!(
        with.log[0].loss > without.log[0].loss,
        "first loss with the term {} not above without it {}",
        with.log[0].loss,
        without.log[0].loss
    );
    let plain = serde_json::to_value(&plain_cfg).unwrap();
    assert!(plain.get("color_mean").is_none(), "the default weight is written: {plain}");
    assert_eq!(serde_json::from_value::<TrainConfig>(plain).unwrap().color_mean, 0.0);
    assert_eq!(serde_json::to_value(&cfg).unwrap()["color_mean"], 5.0);
    let mut bad = config(20);
    bad.color_mean = -1.0;
    assert!(bad.validate().unwrap_err().to_string().contains("colour-mean"));
}

/// The patch MLP trains in the same loop, on the same crops and loss, and its weights load back as one.
#[test]
fn the_patch_mlp_trains_like_the_unets() {
    let samples = synthetic(4);
    let mut cfg = config(30);
    cfg.net = PatchMlpConfig::burger(3, 0.03, Activation::Tanh).into();
    let trained = run(&cfg, &samples).unwrap();
    let l = losses(&trained);
    let first: f64 = l[..5].iter().sum::<f64>() / 5.0;
    let last: f64 = l[25..].iter().sum::<f64>() / 5.0;
    assert!(last < 0.5 * first, "loss did not drop enough: first steps {first:.4}, last steps {last:.4}: {l:?}");
    let (net, info) = load_model(&trained.weights, &Device::Cpu).unwrap();
    assert!(matches!(net, hush_net::Net::PatchMlp(_)));
    assert_eq!(info.net, cfg.net);
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

/// `hush train`'s defaults (color + albedo + normal, `unet` at width 0.25, batch 4, 64² crops, L_MIX, Adam at
/// 1e-3) run with every core the machine has (2 on CI; candle's GEMM and convolutions split their work
/// across them): two runs give bit-identical losses and weights. Measured by hand as well with
/// RAYON_NUM_THREADS=1 against 2, which also agree bit for bit.
#[test]
fn same_seed_same_losses_at_the_default_configuration() {
    let features = InputFeatures::parse("color,albedo,normal").unwrap();
    let samples: Vec<TrainSample> = (0..2)
        .map(|k| {
            let target =
                Image::from_fn(64, 64, 3, |x, y, c| 0.1 + 0.8 * ((x * (c + 1) + y * (k + 2)) % 64) as f32 / 64.0);
            let mut input = Image::from_fn(64, 64, 9, |x, y, c| target.data[(y * 64 + x) * 3 + c % 3]);
            for (i, v) in input.data.iter_mut().enumerate() {
                *v = (*v + 0.3 * noise(i, k as u64)).clamp(0.0, 1.0);
            }
            TrainSample { input, target }
        })
        .collect();
    let mut cfg = TrainConfig::thesis(features);
    cfg.net = UNetConfig::new(UNetKind::Unet, 9, 0.25).into();
    (cfg.steps, cfg.crop, cfg.lr, cfg.eval_every) = (2, 64, 1e-3, 0);
    let a = run(&cfg, &samples).unwrap();
    let b = run(&cfg, &samples).unwrap();
    assert_eq!(losses(&a), losses(&b));
    assert!(a.weights == b.weights, "the weights after two identical runs differ");
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
    let TrainError::Diverged { step, batch, last_good, .. } = err else { panic!("expected Diverged, got {msg}") };
    assert_eq!(step, 1);
    assert!(batch.contains("sample 0") && batch.contains("sample 1"), "{batch}");
    assert!(last_good.log.is_empty());
    let (_, info) = load_model(&last_good.weights, &Device::Cpu).unwrap();
    assert_eq!(info, cfg.model_info());
}

/// Every epoch ends with its metrics and a checkpoint that `hush denoise` can load as a model; the test
/// loss is measured every `eval_every` epochs and at the end, and the best one is marked.
#[test]
fn epochs_report_metrics_and_checkpoints() {
    let samples = synthetic(4);
    let test = synthetic(1);
    let mut cfg = config(7);
    (cfg.batch, cfg.eval_every) = (2, 2); // 2 steps per epoch: epochs end at steps 2, 4, 6 and 7
    let mut got = Vec::new();
    let trained = train(&cfg, &samples, &test, &Device::Cpu, Start::Fresh, |r| {
        if let Some((row, bytes)) = r.epoch {
            got.push((row, bytes));
        }
        ControlFlow::Continue(())
    })
    .unwrap();
    let rows: Vec<EpochRow> = got.iter().map(|(r, _)| *r).collect();
    assert_eq!(rows.iter().map(|r| (r.epoch, r.step)).collect::<Vec<_>>(), vec![(1, 2), (2, 4), (3, 6), (4, 7)]);
    assert_eq!(rows.iter().map(|r| r.test_loss.is_some()).collect::<Vec<_>>(), vec![false, true, false, true]);
    assert_eq!(rows, trained.epochs);
    let log = &trained.log;
    assert_eq!(rows[1].train_loss, (log[2].loss + log[3].loss) / 2.0);
    assert!(rows[1].best, "the first test loss is the best so far");
    assert_eq!(rows[3].best, rows[3].test_loss.unwrap() < rows[1].test_loss.unwrap());
    assert!(rows.iter().all(|r| (0.0..=1.0).contains(&r.loader_share)));
    for (row, bytes) in &got {
        let (_, info) = load_model(bytes, &Device::Cpu).unwrap();
        assert_eq!(info, cfg.model_info());
        let state = read_train_state(bytes).unwrap().unwrap();
        assert_eq!((state.step, state.epoch, state.crops_drawn), (row.step, row.epoch, 2 * row.step as u64));
        assert_eq!(state.config, cfg);
    }
    assert_eq!(read_train_state(&trained.weights).unwrap(), None, "the final weights are a plain model");
    let svg = plot_losses(&rows, 320, 200);
    assert_eq!(hush_plot::texts(&svg, "legend"), ["training loss (epoch mean)", "test loss"]);
    assert_eq!(hush_plot::texts(&svg, "x-title"), ["epoch"]);
    assert!(hush_plot::texts(&svg, "y-title")[0].ends_with("(log scale)"));
}

/// Resuming from a mid-run checkpoint continues exactly: the same losses, step for step, and the same
/// final weights as the uninterrupted run, for Adam with a schedule and for SGD with momentum.
#[test]
fn resume_continues_exactly() {
    let samples = synthetic(3);
    for (optimizer, schedule) in [
        (OptimizerConfig::adam(), Schedule::Cosine { min_lr: 0.0, t_max: 0 }),
        (OptimizerConfig::sgd(0.9), Schedule::Constant),
    ] {
        let mut cfg = config(6);
        (cfg.batch, cfg.optimizer, cfg.schedule, cfg.augment) = (2, optimizer, schedule, Augment::FlipsPermute);
        let mut checkpoint = None;
        let full = train(&cfg, &samples, &[], &Device::Cpu, Start::Fresh, |r| {
            if let Some((row, bytes)) = r.epoch
                && row.step == 2
            {
                checkpoint = Some(bytes);
            }
            ControlFlow::Continue(())
        })
        .unwrap();
        let resumed =
            train(
                &cfg,
                &samples,
                &[],
                &Device::Cpu,
                Start::Resume(&checkpoint.unwrap()),
                |_| ControlFlow::Continue(()),
            )
            .unwrap();
        assert_eq!(resumed.log.iter().map(|r| r.step).collect::<Vec<_>>(), vec![3, 4, 5, 6]);
        let tail: Vec<(f64, f64)> = full.log[2..].iter().map(|r| (r.loss, r.lr)).collect();
        assert_eq!(resumed.log.iter().map(|r| (r.loss, r.lr)).collect::<Vec<_>>(), tail, "{:?}", cfg.optimizer);
        assert_eq!(resumed.weights, full.weights, "{:?}", cfg.optimizer);
    }
}

/// A checkpoint refuses to continue another network or feature set, naming both, and another optimizer.
#[test]
fn resume_refuses_another_run() {
    let samples = synthetic(2);
    let mut cfg = config(2);
    cfg.batch = 2;
    let mut checkpoint = None;
    train(&cfg, &samples, &[], &Device::Cpu, Start::Fresh, |r| {
        checkpoint = r.epoch.map(|(_, b)| b).or(checkpoint.take());
        ControlFlow::Continue(())
    })
    .unwrap();
    let checkpoint = checkpoint.unwrap();
    let resume = |c: &TrainConfig, s: &[TrainSample]| {
        train(c, s, &[], &Device::Cpu, Start::Resume(&checkpoint), |_| ControlFlow::Continue(()))
            .unwrap_err()
            .to_string()
    };
    let mut wider = cfg.clone();
    (wider.net, wider.steps) = (UNetConfig { width: 0.5, ..cfg.net.as_unet().unwrap().clone() }.into(), 4);
    let err = resume(&wider, &samples);
    assert!(err.contains("cannot resume") && err.contains("width 0.25") && err.contains("width 0.5"), "{err}");

    let mut with_normals = cfg.clone();
    with_normals.features = InputFeatures::parse("nrm").unwrap();
    with_normals.net = cfg.net.with_in_channels(6);
    let normal = Image::from_fn(32, 32, 3, |_, _, c| if c == 2 { 1.0 } else { 0.0 });
    let six: Vec<TrainSample> = samples
        .iter()
        .map(|s| TrainSample { input: Image::concat_channels(&[&s.input, &normal]).unwrap(), target: s.target.clone() })
        .collect();
    let err = resume(&with_normals, &six);
    assert!(err.contains("on features hdr, but") && err.contains("on features hdr,nrm"), "{err}");

    let mut sgd = cfg.clone();
    (sgd.optimizer, sgd.steps) = (OptimizerConfig::sgd(0.9), 4);
    assert!(resume(&sgd, &samples).contains("optimizer"));
    let mut other_seed = cfg.clone();
    (other_seed.seed, other_seed.steps) = (99, 4);
    let err = resume(&other_seed, &samples);
    assert!(err.contains("seed: 11 in the checkpoint, 99 now"), "{err}");
}

/// Gradient clipping keeps a step with a huge learning rate bounded: after one SGD step at lr 1e3 with the
/// gradient norm clipped to 1e-6, no weight moves by more than 1e-3.
#[test]
fn gradient_clipping_bounds_the_update() {
    let samples = synthetic(2);
    let mut cfg = config(1);
    (cfg.optimizer, cfg.lr, cfg.clip_grad_norm) = (OptimizerConfig::sgd(0.0), 1e3, Some(1e-6));
    let before = run(
        &{
            let mut c = cfg.clone();
            c.lr = 1e-30;
            c
        },
        &samples,
    )
    .unwrap();
    let after = run(&cfg, &samples).unwrap();
    let weights = |t: &Trained| -> Vec<f32> {
        let (net, _) = load_model(&t.weights, &Device::Cpu).unwrap();
        net.named_tensors().iter().flat_map(|(_, t)| t.flatten_all().unwrap().to_vec1::<f32>().unwrap()).collect()
    };
    let moved = weights(&before).iter().zip(weights(&after)).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
    assert!(moved > 0.0 && moved <= 1e-3, "largest change {moved}");
}

#[test]
fn observer_can_stop_training() {
    let samples = synthetic(2);
    let trained = train(&config(10), &samples, &[], &Device::Cpu, Start::Fresh, |r| {
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
    cfg.features = InputFeatures::parse("alb").unwrap();
    assert!(run(&cfg, &samples).unwrap_err().to_string().contains("input channels"));
    cfg.net = cfg.net.with_in_channels(6);
    assert!(run(&cfg, &samples).unwrap_err().to_string().contains("training sample 0: input has 3 channels"));
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
    let features = InputFeatures::parse("nrm").unwrap();
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

/// Starting from trained weights: the run's first loss is the trained model's (it starts where that model
/// ended, not from random weights), and weights or a configuration that do not match are refused.
#[test]
fn training_starts_from_trained_weights() {
    let samples = synthetic(2);
    let first = run(&config(30), &samples).unwrap();
    let weights = hush_net::Pretrained::read(&first.weights, &Device::Cpu).unwrap();
    let mut cfg = config(1);
    cfg.init = Some(hush_train::InitRecord::of("first.safetensors", &first.weights, weights.info.features.clone()));
    let from_trained =
        train(&cfg, &samples, &[], &Device::Cpu, Start::Init(&weights), |_| ControlFlow::Continue(())).unwrap();
    let from_random = run(&config(1), &samples).unwrap();
    let (start, random) = (from_trained.log[0].loss, from_random.log[0].loss);
    let trained_loss = first.log.last().unwrap().loss;
    assert!(start < random && (start - trained_loss).abs() < (random - trained_loss).abs(), "{start} {random}");

    let err = run(&cfg, &samples).unwrap_err().to_string();
    assert!(err.contains("starts from first.safetensors") && err.contains("no initial weights"), "{err}");
    let mut wider = cfg.clone();
    wider.net = UNetConfig { width: 0.5, ..cfg.net.as_unet().unwrap().clone() }.into();
    let err = train(&wider, &samples, &[], &Device::Cpu, Start::Init(&weights), |_| ControlFlow::Continue(()))
        .unwrap_err()
        .to_string();
    assert!(err.contains("width 0.25") && err.contains("width 0.5"), "{err}");
    let unrecorded = config(1);
    let err = train(&unrecorded, &samples, &[], &Device::Cpu, Start::Init(&weights), |_| ControlFlow::Continue(()))
        .unwrap_err()
        .to_string();
    assert!(err.contains("does not record them"), "{err}");

    // Fine-tuning only the output layer: every other tensor keeps the initial weights bit for bit, and the
    // output layer moves; a layer the network lacks is refused with the ones it has.
    let mut last_only = cfg.clone();
    last_only.steps = 3;
    last_only.trainable = vec!["dec_conv0".into()];
    let tuned =
        train(&last_only, &samples, &[], &Device::Cpu, Start::Init(&weights), |_| ControlFlow::Continue(())).unwrap();
    let tensors = |bytes: &[u8]| candle_core::safetensors::load_buffer(bytes, &Device::Cpu).unwrap();
    let (before, after) = (tensors(&first.weights), tensors(&tuned.weights));
    for (name, t) in &before {
        let same = t.flatten_all().unwrap().to_vec1::<f32>().unwrap()
            == after[name].flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_eq!(same, !name.starts_with("dec_conv0."), "{name}");
    }
    last_only.trainable = vec!["dec_conv9".into()];
    let err = train(&last_only, &samples, &[], &Device::Cpu, Start::Init(&weights), |_| ControlFlow::Continue(()))
        .unwrap_err()
        .to_string();
    assert!(err.contains("no layer dec_conv9") && err.contains("enc_conv0"), "{err}");
}
