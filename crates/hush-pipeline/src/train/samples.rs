//! The prepared samples of a dataset split, cached beside the dataset as f16 under a key that says what they
//! were made from, so a second run over the same data starts at once.

use std::path::Path;

use anyhow::{Context, Result, bail};
use hush_dataset::{Image, ViewRecord, load_render_with};
use hush_hash::fnv1a;
use hush_net::transfer::Transfer;
use hush_train::{PREPARATION_VERSION, TrainSample, decode_samples, round_trip};

use super::RunConfig;
use super::folder::write_file;
use crate::Observer;
use crate::eval::aux_of;

/// Which of a run's sample sets [`load_split`] prepares: it names the cache file, and only training samples
/// must hold a whole crop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Role {
    Train,
    Validation,
    Test,
}

/// The samples of `views` (one split, or the validation scenes) at the configured spp, named
/// `scene_view@spp`: from their f16 cache beside the dataset (`DATASET/cache/`) when it is intact and was
/// made from these records, feature set, transfer and spp; otherwise prepared from the EXR files and cached
/// for the next run.
pub(crate) fn load_split(
    cfg: &RunConfig,
    views: &[&ViewRecord],
    role: Role,
    observer: &dyn Observer,
) -> Result<(Vec<TrainSample>, Vec<String>)> {
    let features = &cfg.train.features;
    let records: Vec<_> = views
        .iter()
        .flat_map(|&view| {
            view.noisy.iter().filter(|r| cfg.spp.is_empty() || cfg.spp.contains(&r.spp)).map(move |r| (view, r))
        })
        .collect();
    let names: Vec<String> =
        records.iter().map(|(view, r)| format!("{}_{}@{}spp", view.scene, view.view, r.spp)).collect();
    // The file is named by what the samples are (features, transfer, split, views and spp), so a changed
    // dataset replaces its cache rather than adding one; the key inside also covers the records of this
    // split's views (files, seeds, sizes) and how samples are prepared, and a mismatch rebuilds the file.
    let what = format!(
        "features {features} ({} aux), transfer {:?}, {role:?} split, samples {}",
        cfg.aux,
        Transfer::Pu,
        names.join(" ")
    );
    let key = format!("views {:016x}, preparation {PREPARATION_VERSION}, {what}", fnv1a(&serde_json::to_vec(&views)?));
    let path = cfg.dataset.join("cache").join(format!("{role:?}-{:016x}.f16", fnv1a(what.as_bytes())).to_lowercase());
    let samples = cached_samples(&path, &key, observer, || {
        let mut samples = Vec::new();
        let variance = features.aux.contains(&hush_net::Feature::Variance);
        // A view's renders follow each other: its reference is read once.
        let mut reference: Option<(&ViewRecord, Image)> = None;
        for &(view, render) in &records {
            let spp = render.spp;
            let known = reference.as_ref().filter(|(v, _)| std::ptr::eq(*v, view)).map(|(_, image)| image.clone());
            let read = known.is_none();
            let images = load_render_with(&cfg.dataset, view, render, cfg.aux, variance, known)?;
            if read {
                reference = Some((view, images.reference.clone()));
            }
            let aux = features
                .aux
                .iter()
                .map(|&f| aux_of(&images, f).with_context(|| format!("{}_{} at {spp} spp", view.scene, view.view)))
                .collect::<Result<Vec<&Image>>>()?;
            samples.push(TrainSample::from_linear(features, Transfer::Pu, &images.color, &aux, &images.reference)?);
        }
        Ok(samples)
    })?;
    if role == Role::Train {
        for (s, name) in samples.iter().zip(&names) {
            if s.input.width.min(s.input.height) < cfg.train.crop {
                bail!(
                    "{name} is {}×{}, smaller than --crop {}: use a smaller crop or a larger dataset --size",
                    s.input.width,
                    s.input.height,
                    cfg.train.crop
                );
            }
        }
    }
    Ok((samples, names))
}

/// Prepared samples from the cache file `path` if it holds intact samples of `key`; otherwise from `build`,
/// written to `path` (atomically) for the next run. Either way the samples are what the cache gives back
/// (values rounded to f16), so a run trains on the same data whether its cache was built or read. A cache
/// that cannot be written (a read-only dataset) is a warning.
pub(crate) fn cached_samples(
    path: &Path,
    key: &str,
    observer: &dyn Observer,
    build: impl FnOnce() -> Result<Vec<TrainSample>>,
) -> Result<Vec<TrainSample>> {
    match std::fs::read(path) {
        Ok(bytes) => match decode_samples(&bytes, key) {
            Ok(samples) => return Ok(samples),
            Err(e) => observer.note(&format!("warning: {}: {e}; preparing the samples again", path.display())),
        },
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => observer.note(&format!("warning: cannot read {}: {e}; preparing the samples again", path.display())),
    }
    let samples = build()?;
    let (samples, bytes) = round_trip(key, &samples)?;
    let written = match path.parent() {
        Some(dir) => std::fs::create_dir_all(dir)
            .with_context(|| format!("creating {}", dir.display()))
            .and_then(|()| write_file(path, &bytes)),
        None => Ok(()),
    };
    if let Err(e) = written {
        observer
            .note(&format!("warning: the sample cache is not saved ({e:#}); the next run prepares the samples again"));
    }
    Ok(samples)
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;

    use hush_dataset::Image;
    use hush_train::TrainSample;

    use super::cached_samples;

    fn samples(value: f32) -> Vec<TrainSample> {
        let input = Image::from_fn(4, 4, 9, |x, y, c| value + 0.01 * (x + 2 * y + c) as f32);
        let target = Image::from_fn(4, 4, 3, |x, _, _| value + 0.1 * x as f32);
        vec![TrainSample { input, target }]
    }

    /// A missing, stale or damaged cache is rebuilt and rewritten; an intact one is read without preparing
    /// anything; a run gets the same values either way.
    #[test]
    fn the_sample_cache_is_rebuilt_unless_intact() {
        let dir = std::env::temp_dir().join(format!("hush-sample-cache-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("cache").join("train.f16");
        let builds = Cell::new(0);
        let load = |key: &str, value: f32| {
            cached_samples(&path, key, &crate::Quiet, || {
                builds.set(builds.get() + 1);
                Ok(samples(value))
            })
            .unwrap()
        };
        let fresh = load("a", 0.25);
        assert_eq!(builds.get(), 1);
        assert!(path.is_file(), "the cache is written");
        assert_eq!(load("a", 0.25), fresh, "read back: the same values");
        assert_eq!(builds.get(), 1, "an intact cache is trusted");

        // Damaged (one byte changed), then cut short: prepared again, not trusted.
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[40] ^= 1;
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(load("a", 0.25), fresh);
        assert_eq!(builds.get(), 2);
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        assert_eq!(load("a", 0.25), fresh);
        assert_eq!(builds.get(), 3);
        assert_eq!(load("a", 0.25), fresh);
        assert_eq!(builds.get(), 3, "the rebuilt cache is intact again");

        // Another key (the dataset or the settings changed): the new data, not the cached one.
        let other = load("b", 0.5);
        assert_eq!(builds.get(), 4);
        assert_ne!(other, fresh);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
