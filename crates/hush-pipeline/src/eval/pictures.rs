//! The pictures of an evaluation: crops of the window where the noisy input is worst, and difference
//! pictures marking the pixels off by more than 3 % and 10 %.

use std::path::Path;

use anyhow::{Context, Result};
use hush_dataset::{Image, write_atomic};
use hush_eval::pictures::{self, Rgb8};
use hush_eval::viewer::file_safe;
use hush_eval::{Figure, FigureImage, FigureKind, NOISY, REFERENCE};

/// The crops side by side (each output, then the reference) and the difference pictures of one view,
/// written to `dir` (`pictures/` of the report).
pub(crate) fn pictures_of(
    dir: &Path,
    view: &str,
    spp: u32,
    outputs: &[(String, Image)],
    reference: &Image,
    exposure: f32,
) -> Result<Vec<Figure>> {
    let Some((_, noisy)) = outputs.iter().find(|(m, _)| m == NOISY) else { return Ok(Vec::new()) };
    let side = (reference.width.min(reference.height) / 2).clamp(1, 128);
    let zoom = (256 / side).clamp(1, 8);
    let (x, y) = pictures::worst_window(noisy, reference, exposure, side)?;
    let write = |file: String, picture: &Rgb8| -> Result<String> {
        let path = dir.join(&file);
        let png = picture.to_png()?;
        write_atomic(&path, |tmp| std::fs::write(tmp, &png).with_context(|| format!("writing {}", path.display())))?;
        Ok(format!("pictures/{file}"))
    };
    let mut crops = Vec::new();
    let mut diffs = Vec::new();
    let diff_zoom = (256 / reference.width.max(1)).clamp(1, 4);
    for (method, image) in outputs.iter().map(|(m, i)| (m.as_str(), i)).chain([(REFERENCE, reference)]) {
        let crop = Rgb8::tonemapped(image, exposure)?.crop(x, y, side, side).upscale(zoom);
        let path = write(format!("{view}_{spp:06}_{}_crop.png", file_safe(method)), &crop)?;
        crops.push(FigureImage { method: Some(method.to_string()), ..FigureImage::new(method, path) });
        if method != REFERENCE {
            let (picture, marks) = pictures::error_marks(image, reference, exposure)?;
            let path = write(format!("{view}_{spp:06}_{}_diff.png", file_safe(method)), &picture.upscale(diff_zoom))?;
            let caption =
                format!("{method}: {:.1} % > 3 %, {:.1} % > 10 %", 100.0 * marks.over_low, 100.0 * marks.over_high);
            diffs.push(FigureImage {
                method: Some(method.to_string()),
                marks: Some(marks),
                ..FigureImage::new(caption, path)
            });
        }
    }
    Ok(vec![
        Figure {
            title: format!("{view} at {spp} spp: crops"),
            kind: FigureKind::Crops { view: view.to_string(), spp },
            images: crops,
            note: format!(
                "The {side}×{side} window at ({x}, {y}) where the noisy input is worst, tonemapped as the metrics \
                 are, enlarged {zoom}×."
            ),
        },
        Figure {
            title: format!("{view} at {spp} spp: pixels off by more than 3 % and 10 %"),
            kind: FigureKind::Differences { view: view.to_string(), spp },
            images: diffs,
            note: "Yellow: the tonemapped value of some channel is off by more than 3 % of the range; red: by more \
                   than 10 % (the thresholds of the thesis's figures 7.7 and 7.3); grey: the reference, dimmed."
                .into(),
        },
    ])
}
