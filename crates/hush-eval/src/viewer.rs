//! The image comparison at the top of `report.html`: per test view one image area that flips between the
//! noisy input, each denoiser and the reference (buttons or keys), a split between any two, zoom to pixels
//! and pan (one view for every image), exposure, an error view against the reference with its colour scale,
//! and each image's metrics beside its name.
//!
//! The images stay HDR: each is stored beside the report as half floats ([`encode_hdr`]: little-endian
//! IEEE 754 binary16 RGB, row-major from the top, the low bytes of all values then the high bytes, then zlib),
//! inlined into the page as base64 and decoded there, so exposure shows what is in the data. The page
//! tonemaps as the metrics do ([`crate::tonemap`]: OIDN's filmic curve and sRGB at the reference's
//! autoexposure, times 2^EV).

use std::fmt::Write as _;
use std::io::{Read as _, Write as _};
use std::path::Path;

use hush_dataset::Image;
use serde::{Deserialize, Serialize};

use crate::html::{base64, escape_html};
use crate::report::{psnr_text, write_file};
use crate::{Error, REFERENCE, Report, Result};

/// The file name ending of [`encode_hdr`]'s files.
pub const HDR_EXTENSION: &str = "rgbh.zz";

/// One view's comparison: what [`crate::html`] turns into the viewer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Viewer {
    pub view: String,
    /// The spp of the noisy input the denoisers were given.
    pub spp: u32,
    pub width: usize,
    pub height: usize,
    /// The exposure of the evaluation tonemap (the reference's autoexposure): EV 0 in the page.
    pub exposure: f32,
    /// In order: the noisy input, each denoiser, the reference last.
    pub images: Vec<ViewerImage>,
}

/// One image of a [`Viewer`]: its method and its [`encode_hdr`] file relative to the report folder.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ViewerImage {
    pub method: String,
    pub path: String,
}

impl Viewer {
    /// Writes each image as `pictures/<view>_<spp>_<method>.rgbh.zz` into `dir` (the report folder) and
    /// returns the viewer; `outputs` are (method, image) with the noisy input first, the reference is added.
    pub fn write(
        dir: &Path,
        view: &str,
        spp: u32,
        outputs: &[(String, Image)],
        reference: &Image,
        exposure: f32,
    ) -> Result<Viewer> {
        let pictures = dir.join("pictures");
        std::fs::create_dir_all(&pictures).map_err(|source| Error::File {
            path: pictures.clone(),
            action: "create the pictures folder",
            source,
        })?;
        let mut images = Vec::new();
        for (method, image) in outputs.iter().map(|(m, i)| (m.as_str(), i)).chain([(REFERENCE, reference)]) {
            if (image.width, image.height, image.channels) != (reference.width, reference.height, 3) {
                return Err(Error::Shape(format!(
                    "viewer of {view}: {method} is {} but the reference is {}",
                    image.size_string(),
                    reference.size_string()
                )));
            }
            let path = format!("pictures/{view}_{spp:06}_{}.{HDR_EXTENSION}", file_safe(method));
            write_file(&dir.join(&path), &encode_hdr(image)?)?;
            images.push(ViewerImage { method: method.to_string(), path });
        }
        Ok(Viewer { view: view.into(), spp, width: reference.width, height: reference.height, exposure, images })
    }
}

/// A method name as part of a file name: `/` and other unsafe characters become `-`.
pub fn file_safe(method: &str) -> String {
    method.chars().map(|c| if c.is_ascii_alphanumeric() || "._-".contains(c) { c } else { '-' }).collect()
}

/// An RGB image as zlib-compressed half floats, the low bytes of every value before the high bytes (which
/// compresses better: the high bytes, sign and exponent, repeat). Values beyond half's range become ±Inf,
/// NaN stays NaN.
pub fn encode_hdr(image: &Image) -> Result<Vec<u8>> {
    if image.channels != 3 {
        return Err(Error::Shape(format!("the viewer stores RGB images, got a {} image", image.size_string())));
    }
    let halves: Vec<u16> = image.data.iter().map(|&v| half::f16::from_f32(v).to_bits()).collect();
    let mut planes = Vec::with_capacity(2 * halves.len());
    planes.extend(halves.iter().map(|h| (h & 0xff) as u8));
    planes.extend(halves.iter().map(|h| (h >> 8) as u8));
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(6));
    z.write_all(&planes).and_then(|()| z.finish()).map_err(|e| Error::Picture(format!("compressing an image: {e}")))
}

/// The inverse of [`encode_hdr`] for a `width`×`height` image.
pub fn decode_hdr(bytes: &[u8], width: usize, height: usize) -> Result<Image> {
    let n = width * height * 3;
    let mut planes = Vec::with_capacity(2 * n);
    let mut z = flate2::read::ZlibDecoder::new(bytes).take(2 * n as u64 + 1);
    z.read_to_end(&mut planes).map_err(|e| Error::Picture(format!("decompressing an image: {e}")))?;
    if planes.len() != 2 * n {
        return Err(Error::Shape(format!(
            "a viewer image of {width}x{height} holds {} bytes of half floats, not {}",
            planes.len(),
            2 * n
        )));
    }
    let data = (0..n).map(|i| half::f16::from_bits(u16::from(planes[i]) | u16::from(planes[n + i]) << 8).to_f32());
    Ok(Image { width, height, channels: 3, data: data.collect() })
}

/// What the page shows beside an image's name: PSNR, relMSE and FLIP from the report's row.
fn metrics_text(report: &Report, view: &str, method: &str, spp: u32) -> String {
    if method == REFERENCE {
        return report
            .rows
            .iter()
            .find(|r| r.view == view && r.method == REFERENCE)
            .map(|r| format!("{} spp", r.spp))
            .unwrap_or_default();
    }
    let Some(r) = report.rows.iter().find(|r| r.view == view && r.method == method && r.spp == spp) else {
        return String::new();
    };
    let mut s = format!("PSNR {} dB · relMSE {:.2e}", psnr_text(r.psnr), r.rel_mse);
    if let Some(f) = r.flip {
        let _ = write!(s, " · FLIP {f:.3}");
    }
    s
}

/// JSON safe inside `<script>`: `<` is escaped, so no `</script>` can end the element early.
fn script_json(value: &serde_json::Value) -> String {
    value.to_string().replace('<', "\\u003c")
}

/// One viewer as HTML (`index` numbers it on the page); its images are read from `dir` and inlined.
pub(crate) fn to_html(report: &Report, viewer: &Viewer, dir: &Path, index: usize) -> Result<String> {
    let mut data = Vec::new();
    let mut picks = String::new();
    let mut others = String::new();
    for (i, image) in viewer.images.iter().enumerate() {
        let file = dir.join(&image.path);
        let bytes = std::fs::read(&file).map_err(|source| Error::File {
            path: file.clone(),
            action: "read for report.html",
            source,
        })?;
        let metrics = metrics_text(report, &viewer.view, &image.method, viewer.spp);
        let key = if image.method == REFERENCE {
            "r".to_string()
        } else if i < 9 {
            (i + 1).to_string()
        } else {
            String::new()
        };
        data.push(serde_json::json!({"method": image.method, "metrics": metrics, "data": base64(&bytes)}));
        let _ = write!(
            picks,
            "<button type=\"button\" class=\"hv-pick\" data-i=\"{i}\"><kbd>{key}</kbd> <b>{}</b> <span class=\"hv-m\">{}</span></button>",
            escape_html(&image.method),
            escape_html(&metrics)
        );
        let selected = if i + 1 == viewer.images.len() { " selected" } else { "" };
        let _ = write!(others, "<option value=\"{i}\"{selected}>{}</option>", escape_html(&image.method));
    }
    let json = serde_json::json!({
        "view": viewer.view, "spp": viewer.spp, "width": viewer.width, "height": viewer.height,
        "exposure": viewer.exposure, "images": data,
    });
    // The canvas: the image enlarged by a whole factor to about 512 pixels, at most 900 wide.
    let k = (512 / viewer.width.max(viewer.height).max(1)).max(1);
    let (cw, ch) = ((viewer.width * k).min(900), (viewer.height * k).min(700));
    let mut h = String::new();
    let _ = write!(
        h,
        "<section class=\"hush-viewer\" id=\"viewer-{index}\" tabindex=\"0\">\
         <h3>{} at {} spp: the images</h3><div class=\"hv-body\"><div class=\"hv-stage\" style=\"width:{cw}px\">\
         <canvas class=\"hv-canvas\" width=\"{cw}\" height=\"{ch}\"></canvas>\
         <div class=\"hv-readout\">Point at the image to read a pixel.</div></div><div class=\"hv-side\">\
         <div class=\"hv-list\">{picks}</div>\
         <label>Show <select class=\"hv-mode\"><option value=\"single\">one image</option>\
         <option value=\"split\">split: picked | right side</option><option value=\"error\">error against the reference</option></select></label>\
         <label>Right side of the split <select class=\"hv-other\">{others}</select></label>\
         <label>Split at <input type=\"range\" class=\"hv-split\" min=\"0\" max=\"1\" step=\"0.001\" value=\"0.5\"></label>\
         <label>Exposure <input type=\"range\" class=\"hv-exposure\" min=\"-10\" max=\"10\" step=\"0.25\" value=\"0\"> \
         <output class=\"hv-ev\">+0.00 EV</output></label>\
         <label>Error <select class=\"hv-error\"><option value=\"rel\">relative: |x − ref| / (ref + 0.01), linear HDR</option>\
         <option value=\"abs\">absolute, tonemapped: |tm(x) − tm(ref)|</option></select></label>\
         <label>Error scale up to <select class=\"hv-max\"><option>0.01</option><option>0.03</option>\
         <option selected>0.1</option><option>0.3</option><option>1</option></select></label>\
         <div class=\"hv-scale\"><canvas class=\"hv-scale-bar\" width=\"240\" height=\"12\"></canvas>\
         <div class=\"hv-scale-labels\"><span>0</span><span class=\"hv-scale-mid\">0.05</span><span class=\"hv-scale-max\">0.1</span></div></div>\
         <div>Zoom <button type=\"button\" class=\"hv-zoom-in\">+</button> <button type=\"button\" class=\"hv-zoom-out\">−</button> \
         <button type=\"button\" class=\"hv-fit\">fit</button> <output class=\"hv-zoom\"></output></div>\
         <p class=\"small\">Keys: 1–9 pick an image, r the reference, s split, e error, o one image, + and − zoom, 0 fit, \
         [ and ] exposure. Drag to pan, the wheel zooms at the cursor. The images are {}×{} HDR (half floats), tonemapped \
         in the page as the metrics are.</p>\
         </div></div><script type=\"application/json\" class=\"hv-data\">{}</script></section>",
        escape_html(&viewer.view),
        viewer.spp,
        viewer.width,
        viewer.height,
        script_json(&json)
    );
    h.push('\n');
    Ok(h)
}

/// The viewer's style rules.
pub(crate) const STYLE: &str = ".hush-viewer{border:1px solid #ccc;padding:0.5em;margin:0 0 1.5em;outline:none}\
.hush-viewer:focus-within,.hush-viewer:focus{border-color:#4a7}.hv-body{display:flex;gap:1em;flex-wrap:wrap}\
.hv-canvas{background:#333;cursor:crosshair;image-rendering:pixelated;touch-action:none;max-width:100%}\
.hv-side{flex:1;min-width:280px;font-size:90%}.hv-side label{display:block;margin:0.35em 0}\
.hv-pick{display:block;width:100%;text-align:left;margin:2px 0;padding:3px 6px;border:1px solid #bbb;background:#f7f7f7;cursor:pointer}\
.hv-pick.on{background:#def;border-color:#36c}.hv-pick.right{border-style:dashed}\
.hv-m{color:#555;font-size:90%}.hv-stage{flex:none;max-width:100%}.hv-readout{font-family:monospace;font-size:85%;min-height:4em}\
.hv-scale-labels{display:flex;justify-content:space-between;width:240px;font-size:85%}kbd{border:1px solid #aaa;\
border-radius:3px;padding:0 3px;font-size:85%;background:#fff}";

/// The viewer's script: one for the page, it wires every `.hush-viewer`.
pub(crate) const SCRIPT: &str = include_str!("viewer.js");
