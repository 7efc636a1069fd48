//! The optimizers against Candle's AdamW and against their formulas, and their state round trip.

use std::collections::HashMap;

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{AdamW, Optimizer as _, ParamsAdamW};
use hush_train::{Optimizer, OptimizerConfig};

/// A tiny least-squares problem: y = x·w + b with fixed x and y.
struct Problem {
    x: Tensor,
    y: Tensor,
}

impl Problem {
    fn new() -> Self {
        let dev = Device::Cpu;
        let x: Vec<f32> = (0..5 * 3).map(|i| ((i * 7 % 11) as f32 - 5.0) / 4.0).collect();
        let y: Vec<f32> = (0..5 * 2).map(|i| ((i * 5 % 7) as f32 - 3.0) / 2.0).collect();
        Problem { x: Tensor::from_vec(x, (5, 3), &dev).unwrap(), y: Tensor::from_vec(y, (5, 2), &dev).unwrap() }
    }

    fn vars(&self) -> (Var, Var) {
        let dev = Device::Cpu;
        let w: Vec<f32> = (0..3 * 2).map(|i| 0.1 * i as f32 - 0.2).collect();
        (Var::from_vec(w, (3, 2), &dev).unwrap(), Var::zeros(2, DType::F32, &dev).unwrap())
    }

    fn loss(&self, w: &Var, b: &Var) -> Tensor {
        let pred = self.x.matmul(w.as_tensor()).unwrap().broadcast_add(b.as_tensor()).unwrap();
        (pred - &self.y).unwrap().sqr().unwrap().mean_all().unwrap()
    }
}

fn values(v: &Var) -> Vec<f32> {
    v.as_tensor().flatten_all().unwrap().to_vec1().unwrap()
}

fn named(w: &Var, b: &Var) -> Vec<(String, Var)> {
    vec![("w".into(), w.clone()), ("b".into(), b.clone())]
}

/// Adam (weight decay 0) and AdamW (0.01) give exactly candle_nn::AdamW's weights after every one of 30 steps.
#[test]
fn adam_matches_candle_adamw_step_for_step() {
    let p = Problem::new();
    for weight_decay in [0.0, 0.01] {
        let (w1, b1) = p.vars();
        let (w2, b2) = p.vars();
        let params = ParamsAdamW { lr: 0.05, weight_decay, ..ParamsAdamW::default() };
        let mut theirs = AdamW::new(vec![w1.clone(), b1.clone()], params).unwrap();
        let cfg = OptimizerConfig::Adam { beta1: 0.9, beta2: 0.999, eps: 1e-8, weight_decay };
        let mut ours = Optimizer::new(cfg, named(&w2, &b2)).unwrap();
        for step in 1..=30 {
            theirs.step(&p.loss(&w1, &b1).backward().unwrap()).unwrap();
            ours.step(&p.loss(&w2, &b2).backward().unwrap(), 0.05, 1.0).unwrap();
            assert_eq!(values(&w1), values(&w2), "w after step {step}, weight decay {weight_decay}");
            assert_eq!(values(&b1), values(&b2), "b after step {step}, weight decay {weight_decay}");
        }
        assert!(
            p.loss(&w2, &b2).to_scalar::<f32>().unwrap()
                < 0.9 * p.loss(&p.vars().0, &p.vars().1).to_scalar::<f32>().unwrap()
        );
    }
}

/// SGD with momentum on f(w) = w²/2 (gradient w), against the recurrence b ← μb + g, w ← w − lr·b
/// computed by hand in f64; without momentum it is eq. 4.15, w ← w − μ∇L.
#[test]
fn sgd_follows_its_recurrence() {
    for momentum in [0.0, 0.9] {
        let w = Var::from_vec(vec![1f32, -2.0], 2, &Device::Cpu).unwrap();
        let mut opt = Optimizer::new(OptimizerConfig::sgd(momentum), vec![("w".into(), w.clone())]).unwrap();
        let (mut expect, mut buf) = ([1f64, -2.0], [0f64; 2]);
        for _ in 0..10 {
            let loss = (w.as_tensor().sqr().unwrap().sum_all().unwrap() * 0.5).unwrap();
            opt.step(&loss.backward().unwrap(), 0.1, 1.0).unwrap();
            for i in 0..2 {
                buf[i] = momentum * buf[i] + expect[i];
                expect[i] -= 0.1 * buf[i];
            }
        }
        for (got, want) in values(&w).iter().zip(expect) {
            assert!((*got as f64 - want).abs() < 1e-6, "momentum {momentum}: {got} vs {want}");
        }
    }
}

/// Saving the state after 5 steps and loading it into a fresh optimizer continues bit for bit like the
/// uninterrupted optimizer, for Adam and for SGD with momentum.
#[test]
fn state_round_trip_continues_exactly() {
    let p = Problem::new();
    for cfg in [OptimizerConfig::adam(), OptimizerConfig::sgd(0.9)] {
        let (w1, b1) = p.vars();
        let mut straight = Optimizer::new(cfg.clone(), named(&w1, &b1)).unwrap();
        for _ in 0..10 {
            straight.step(&p.loss(&w1, &b1).backward().unwrap(), 0.02, 1.0).unwrap();
        }
        let (w2, b2) = p.vars();
        let mut first = Optimizer::new(cfg.clone(), named(&w2, &b2)).unwrap();
        for _ in 0..5 {
            first.step(&p.loss(&w2, &b2).backward().unwrap(), 0.02, 1.0).unwrap();
        }
        let state: HashMap<String, Tensor> = first.state().into_iter().collect();
        assert!(!state.is_empty(), "{cfg:?} has state");
        let (w3, b3) = (
            Var::from_tensor(&w2.as_tensor().copy().unwrap()).unwrap(),
            Var::from_tensor(&b2.as_tensor().copy().unwrap()).unwrap(),
        );
        let mut second = Optimizer::new(cfg.clone(), named(&w3, &b3)).unwrap();
        second.load_state(first.step_count(), &state).unwrap();
        for _ in 0..5 {
            second.step(&p.loss(&w3, &b3).backward().unwrap(), 0.02, 1.0).unwrap();
        }
        assert_eq!((values(&w1), values(&b1)), (values(&w3), values(&b3)), "{cfg:?}");
        // Without the state, Adam's bias correction and moments start over and the result differs.
        if matches!(cfg, OptimizerConfig::Adam { .. }) {
            let (w4, b4) = (
                Var::from_tensor(&w2.as_tensor().copy().unwrap()).unwrap(),
                Var::from_tensor(&b2.as_tensor().copy().unwrap()).unwrap(),
            );
            let mut fresh = Optimizer::new(cfg.clone(), named(&w4, &b4)).unwrap();
            fresh.step(&p.loss(&w4, &b4).backward().unwrap(), 0.02, 1.0).unwrap();
            let mut resumed = Optimizer::new(cfg.clone(), named(&w2, &b2)).unwrap();
            resumed.load_state(first.step_count(), &state).unwrap();
            resumed.step(&p.loss(&w2, &b2).backward().unwrap(), 0.02, 1.0).unwrap();
            assert_ne!(values(&w4), values(&w2));
        }
        // Another optimizer's state is refused by name.
        let other = if matches!(cfg, OptimizerConfig::Adam { .. }) {
            OptimizerConfig::sgd(0.9)
        } else {
            OptimizerConfig::adam()
        };
        let mut wrong = Optimizer::new(other, named(&w3, &b3)).unwrap();
        let err = wrong.load_state(5, &state).unwrap_err().to_string();
        assert!(err.contains("has no optim."), "{err}");
    }
}

/// A gradient scale of ½ (gradient clipping) is the same as halving the loss.
#[test]
fn gradient_scale_scales_the_gradient() {
    let p = Problem::new();
    let (w1, b1) = p.vars();
    let (w2, b2) = p.vars();
    let mut a = Optimizer::new(OptimizerConfig::sgd(0.0), named(&w1, &b1)).unwrap();
    let mut b = Optimizer::new(OptimizerConfig::sgd(0.0), named(&w2, &b2)).unwrap();
    a.step(&p.loss(&w1, &b1).backward().unwrap(), 0.1, 0.5).unwrap();
    b.step(&(p.loss(&w2, &b2) * 0.5).unwrap().backward().unwrap(), 0.1, 1.0).unwrap();
    for (x, y) in values(&w1).iter().zip(values(&w2)) {
        assert!((x - y).abs() < 1e-6, "{x} vs {y}");
    }
}
