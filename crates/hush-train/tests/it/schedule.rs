//! Each learning-rate schedule against its formula (thesis §4.4, eqs. 4.18–4.22), epoch by epoch.

use std::f64::consts::PI;

use hush_train::Schedule;

const BASE: f64 = 1e-3;

fn curve(s: &Schedule, epochs: usize) -> Vec<f64> {
    (1..=epochs).map(|e| s.lr(BASE, e, epochs)).collect()
}

fn assert_close(got: &[f64], want: &[f64]) {
    assert_eq!(got.len(), want.len());
    for (e, (g, w)) in got.iter().zip(want).enumerate() {
        assert!((g - w).abs() <= 1e-12 * w.abs().max(1e-12), "epoch {}: {g} vs {w}", e + 1);
    }
}

/// Eq. 4.18: "μ(e) = c".
#[test]
fn constant() {
    assert_eq!(curve(&Schedule::Constant, 50), vec![BASE; 50]);
}

/// Eq. 4.19: "μ(e) = μ_init · λ(e)" with custom factors; the last factor holds after the list.
#[test]
fn lambda_custom_factors() {
    let s = Schedule::Lambda { factors: vec![1.0, 0.5, 0.25, 0.1] };
    assert_close(&curve(&s, 6), &[BASE, 0.5 * BASE, 0.25 * BASE, 0.1 * BASE, 0.1 * BASE, 0.1 * BASE]);
}

/// Eq. 4.19 with the step-decay lambda λ(e) = γ^⌊(e − 1) / every⌋.
#[test]
fn lambda_step_decay() {
    let s = Schedule::Step { every: 3, gamma: 0.1 };
    let want: Vec<f64> = (1..=10).map(|e| BASE * 0.1f64.powi((e - 1) / 3)).collect();
    assert_close(&curve(&s, 10), &want);
    assert_eq!(curve(&s, 10)[..3], [BASE; 3]);
}

/// Eqs. 4.20–4.21: "μ(1) = μ_init", "μ(e+1) = γ · μ(e)" — checked as the recurrence itself.
#[test]
fn exponential() {
    let s = Schedule::Exponential { gamma: 0.9 };
    let c = curve(&s, 20);
    assert_eq!(c[0], BASE);
    for e in 1..20 {
        assert!((c[e] - 0.9 * c[e - 1]).abs() < 1e-15, "epoch {}", e + 1);
    }
}

/// Eq. 4.22: "μ(e) = μ_min + ½(μ_max − μ_min)(1 + cos(T_cur/T_max · π))" with T_cur = e − 1.
#[test]
fn cosine_annealing() {
    let min = 1e-5;
    let s = Schedule::Cosine { min_lr: min, t_max: 0 };
    let epochs = 40;
    let want: Vec<f64> =
        (1..=epochs).map(|e| min + 0.5 * (BASE - min) * (1.0 + ((e - 1) as f64 / epochs as f64 * PI).cos())).collect();
    assert_close(&curve(&s, epochs), &want);
    assert_eq!(curve(&s, epochs)[0], BASE);
    // An explicit T_max shorter than the run.
    let s = Schedule::Cosine { min_lr: 0.0, t_max: 10 };
    assert!((s.lr(BASE, 11, 40) - 0.0).abs() < 1e-18, "T_cur = T_max reaches μ_min");
}

/// SGDR: eq. 4.22 where T_cur restarts at every cycle end, the cycles lasting T_0, T_0·T_mult, T_0·T_mult², ...
#[test]
fn cosine_with_warm_restarts() {
    let s = Schedule::CosineRestarts { t0: 5, t_mult: 2, min_lr: 0.0 };
    let c = curve(&s, 35);
    // Cycles: epochs 1–5 (T_i = 5), 6–15 (10), 16–35 (20).
    let mut want = Vec::new();
    for t_i in [5usize, 10, 20] {
        want.extend((0..t_i).map(|t_cur| 0.5 * BASE * (1.0 + (t_cur as f64 / t_i as f64 * PI).cos())));
    }
    assert_close(&c, &want);
    for restart in [5, 15] {
        assert!(c[restart] > c[restart - 1] && c[restart] == BASE, "warm restart at epoch {}", restart + 1);
    }
}

/// OIDN's one-cycle policy (PyTorch OneCycleLR, cosine, not three-phase): from max/div up to max over the
/// first pct_start · epochs − 1 epochs, then down to max/div/final_div at the last epoch, each half
/// `end + (start − end)/2 · (1 + cos(π · pct))`.
#[test]
fn one_cycle() {
    let s = Schedule::one_cycle();
    let epochs = 100;
    let c = curve(&s, epochs);
    let (initial, min) = (BASE / 25.0, BASE / 25.0 / 1e4);
    let up_end = 0.15 * epochs as f64 - 1.0; // 14
    let want: Vec<f64> = (0..epochs)
        .map(|i| {
            let i = i as f64;
            let anneal = |a: f64, b: f64, pct: f64| b + (a - b) / 2.0 * (1.0 + (PI * pct).cos());
            if i <= up_end {
                anneal(initial, BASE, i / up_end)
            } else {
                anneal(BASE, min, (i - up_end) / (99.0 - up_end))
            }
        })
        .collect();
    assert_close(&c, &want);
    assert!((c[0] - initial).abs() < 1e-15 && (c[14] - BASE).abs() < 1e-15 && (c[99] - min).abs() < 1e-15);
}

#[test]
fn names_parse_with_defaults() {
    assert_eq!(Schedule::parse("constant", 100), Some(Schedule::Constant));
    assert_eq!(Schedule::parse("step:20:0.5", 100), Some(Schedule::Step { every: 20, gamma: 0.5 }));
    assert_eq!(Schedule::parse("lambda:1,0.5", 100), Some(Schedule::Lambda { factors: vec![1.0, 0.5] }));
    assert_eq!(Schedule::parse("exponential:0.95", 100), Some(Schedule::Exponential { gamma: 0.95 }));
    assert_eq!(Schedule::parse("cosine", 100), Some(Schedule::Cosine { min_lr: 0.0, t_max: 0 }));
    assert_eq!(Schedule::parse("sgdr", 100), Some(Schedule::CosineRestarts { t0: 10, t_mult: 2, min_lr: 0.0 }));
    assert_eq!(Schedule::parse("one_cycle", 100), Some(Schedule::one_cycle()));
    assert_eq!(Schedule::parse("warmup", 100), None);
    assert!(Schedule::Step { every: 0, gamma: 0.5 }.validate().is_err());
}
