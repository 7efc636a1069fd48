//! `cargo xtask hostile`: hush against files made to break it, each run as a user would run it, under
//! `/usr/bin/time -v` (peak memory) and `prlimit --as` (4 GB of address space). Every case must end as a
//! clear error or a named warning: exit code 1 with `error:` and the words the case expects (an exit by a
//! signal, a panic or an allocation failure fails the case), or success where a warning names what was
//! skipped; and its peak resident memory must stay under 100 MB. The files are made here, in
//! `target/hostile/files/`; the table of cases (message, exit, peak memory) goes to
//! `target/hostile/summary.json`.

use std::path::Path;
use std::process::Command;

use serde_json::json;

use crate::args::Flags;
use crate::util::{Result, build_hush, ensure_vulkan, project_root, target_dir};

pub const USAGE: &str = "cargo xtask hostile [--release]";

/// The most peak memory a refusal may take.
const MAX_PEAK_MB: f64 = 100.0;
/// What a refusal after the GPU is opened may take above a valid 8² render of the same scene (lavapipe's own
/// memory is the bulk of both).
const GPU_MARGIN_MB: f64 = 20.0;
/// The address space every case runs in: a refusal must not need more.
const ADDRESS_SPACE: &str = "4000000000";

/// One hostile input and the command that reads it.
struct Case {
    name: &'static str,
    /// What the file is, for the table.
    what: &'static str,
    args: Vec<String>,
    /// Environment variables set for this case alone.
    env: Vec<(&'static str, String)>,
    /// Words the output must hold (the file's name, the limit, what is wrong).
    expect: Vec<String>,
    /// Whether hush should succeed with a warning (a skipped texture) rather than fail.
    warns: bool,
    /// The most peak memory it may take: [`MAX_PEAK_MB`], or for a refusal after the GPU is opened, what a
    /// valid 8² render takes plus [`GPU_MARGIN_MB`].
    max_peak_mb: f64,
}

pub fn run(args: &[String]) -> Result<()> {
    let flags = Flags::parse(args, &[("--release", crate::args::Takes::Nothing)], 0, USAGE)?;
    for tool in ["/usr/bin/time", "/usr/bin/prlimit"] {
        if !Path::new(tool).exists() {
            return Err(format!("{tool} is missing: `apt-get install -y time util-linux` installs it"));
        }
    }
    ensure_vulkan()?;
    let hush = build_hush(flags.has("--release"))?;
    let root = target_dir().join("hostile");
    let files = root.join("files");
    if files.exists() {
        std::fs::remove_dir_all(&files).map_err(|e| format!("cannot clear {}: {e}", files.display()))?;
    }
    std::fs::create_dir_all(&files).map_err(|e| format!("cannot create {}: {e}", files.display()))?;
    let cases = make_cases(&hush, &files)?;
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    for case in &cases {
        let (row, problems) = run_case(&hush, case, &files)?;
        eprintln!(
            "{:<28} exit {:<4} peak {:>6.1} MB  {}",
            case.name,
            row["exit"],
            row["peak_mb"].as_f64().unwrap_or(f64::NAN),
            row["message"].as_str().unwrap_or("")
        );
        for p in problems {
            failures.push(format!("{}: {p}", case.name));
        }
        rows.push(row);
    }
    let summary = json!({ "address_space_bytes": ADDRESS_SPACE, "max_peak_mb": MAX_PEAK_MB, "cases": rows });
    crate::util::write_json(&root.join("summary.json"), &summary)?;
    eprintln!("xtask hostile: {} cases; table in {}", cases.len(), root.join("summary.json").display());
    if failures.is_empty() { Ok(()) } else { Err(format!("hostile inputs not handled:\n{}", failures.join("\n"))) }
}

/// Runs one case under `time -v` and `prlimit`; returns its row and what is wrong with its outcome.
fn run_case(hush: &Path, case: &Case, dir: &Path) -> Result<(serde_json::Value, Vec<String>)> {
    let mut cmd = Command::new("/usr/bin/prlimit");
    cmd.arg(format!("--as={ADDRESS_SPACE}")).arg("--").arg("/usr/bin/time").arg("-v").arg(hush).args(&case.args);
    // As a user runs it: RUST_BACKTRACE would make Candle capture (and symbolize) a backtrace in each of its
    // errors, which alone takes about 200 MB.
    cmd.current_dir(dir).env("NODEVICE_SELECT", "1").env_remove("RUST_BACKTRACE");
    for (k, v) in &case.env {
        cmd.env(k, v);
    }
    let out = cmd.output().map_err(|e| format!("{}: cannot start hush: {e}", case.name))?;
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    // time -v reports the command's own status ("Exit status: N", or "Command terminated by signal N").
    let exit =
        stderr.lines().find_map(|l| l.trim().strip_prefix("Exit status: ")).and_then(|v| v.trim().parse::<i64>().ok());
    let signal = stderr.lines().find_map(|l| l.trim().strip_prefix("Command terminated by signal ")).map(str::trim);
    let peak_kb = stderr
        .lines()
        .find_map(|l| l.trim().strip_prefix("Maximum resident set size (kbytes): "))
        .and_then(|v| v.trim().parse::<f64>().ok());
    let hush_text: String =
        stderr.lines().take_while(|l| !l.starts_with("\tCommand being timed")).collect::<Vec<_>>().join("\n");
    let message = hush_text
        .lines()
        .find(|l| l.starts_with("error:") || l.contains("warning"))
        .unwrap_or_else(|| hush_text.lines().last().unwrap_or(""))
        .to_string();
    let mut problems = Vec::new();
    if let Some(sig) = signal {
        problems.push(format!("killed by signal {sig}"));
    }
    if hush_text.contains("panicked") || hush_text.contains("memory allocation of") {
        problems.push("a panic or an allocation failure".into());
    }
    match (case.warns, exit) {
        (false, Some(1)) if hush_text.contains("error:") => {}
        (true, Some(0)) => {}
        (_, e) => problems.push(format!(
            "expected {} but got exit {e:?}",
            if case.warns { "success with a warning" } else { "exit 1 with an error" }
        )),
    }
    for word in &case.expect {
        if !hush_text.contains(word.as_str()) {
            problems.push(format!("the output does not say {word:?}"));
        }
    }
    let peak_mb = peak_kb.map(|k| k / 1024.0);
    if peak_mb.is_none_or(|m| m > case.max_peak_mb) {
        problems.push(format!("peak memory {peak_mb:?} MB, above {} MB", case.max_peak_mb));
    }
    if !problems.is_empty() {
        problems.push(format!("its output:\n{hush_text}"));
    }
    let row = json!({
        "case": case.name,
        "what": case.what,
        "command": format!("hush {}", case.args.join(" ")),
        "exit": exit,
        "signal": signal,
        "peak_mb": peak_mb.map(|m| (m * 10.0).round() / 10.0),
        "max_peak_mb": (case.max_peak_mb * 10.0).round() / 10.0,
        "message": message,
        "ok": problems.is_empty(),
    });
    Ok((row, problems))
}

/// The peak memory (MB) of a valid 8² render of `scene`: what opening the GPU costs.
fn gpu_baseline_mb(hush: &Path, scene: &Path, dir: &Path) -> Result<f64> {
    let out = Command::new("/usr/bin/time")
        .args(["-f", "peak %M"])
        .arg(hush)
        .args(["render", &s(scene), "--spp", "1", "--width", "8", "--height", "8", "--out", "baseline.exr"])
        .current_dir(dir)
        .env("NODEVICE_SELECT", "1")
        .env_remove("RUST_BACKTRACE")
        .output()
        .map_err(|e| format!("cannot start hush: {e}"))?;
    let text = String::from_utf8_lossy(&out.stderr);
    let kb = text.lines().find_map(|l| l.strip_prefix("peak ")).and_then(|v| v.trim().parse::<f64>().ok());
    match (out.status.success(), kb) {
        (true, Some(kb)) => {
            eprintln!("xtask hostile: a valid 8² render takes {:.1} MB at its peak", kb / 1024.0);
            Ok(kb / 1024.0)
        }
        _ => Err(format!("the baseline render failed:\n{text}")),
    }
}

fn write(path: &Path, bytes: impl AsRef<[u8]>) -> Result<()> {
    std::fs::write(path, bytes).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

fn symlink(target: &Path, link: &Path) -> Result<()> {
    std::os::unix::fs::symlink(target, link).map_err(|e| format!("cannot link {}: {e}", link.display()))
}

/// A file of `len` bytes that takes no disk (a hole).
fn sparse(path: &Path, len: u64) -> Result<()> {
    let f = std::fs::File::create(path).map_err(|e| format!("cannot create {}: {e}", path.display()))?;
    f.set_len(len).map_err(|e| format!("cannot size {}: {e}", path.display()))
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// A Mitsuba scene around `body` (a camera, a film of 8², and whatever `body` adds).
fn mitsuba(body: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
{body}
</scene>
"#
    )
}

/// A PNG that declares `w`×`h` 8-bit RGB pixels and holds none.
fn png_header(w: u32, h: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], data: &[u8]| {
        out.extend((data.len() as u32).to_be_bytes());
        let body: Vec<u8> = kind.iter().chain(data).copied().collect();
        out.extend(&body);
        out.extend(crc32(&body).to_be_bytes());
    };
    let mut ihdr = Vec::new();
    ihdr.extend(w.to_be_bytes());
    ihdr.extend(h.to_be_bytes());
    ihdr.extend([8, 2, 0, 0, 0]);
    chunk(b"IHDR", &ihdr);
    chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
    chunk(b"IEND", &[]);
    out
}

/// CRC-32 (ISO-HDLC), as PNG chunks carry it.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xEDB8_8320 } else { crc >> 1 };
        }
    }
    !crc
}

/// `exr` with its data and display windows declared as `side`² (the pixels stay as they were).
fn patch_exr_size(exr: &[u8], side: i32) -> Result<Vec<u8>> {
    let mut out = exr.to_vec();
    let mut patched = 0;
    for key in [&b"dataWindow\0box2i\0"[..], &b"displayWindow\0box2i\0"[..]] {
        let at = out
            .windows(key.len())
            .position(|w| w == key)
            .ok_or_else(|| format!("the EXR hush wrote has no {}", String::from_utf8_lossy(key)))?;
        // After the name and type: the size (16), then x_min, y_min, x_max, y_max.
        let values = at + key.len() + 4;
        out[values + 8..values + 12].copy_from_slice(&(side - 1).to_le_bytes());
        out[values + 12..values + 16].copy_from_slice(&(side - 1).to_le_bytes());
        patched += 1;
    }
    debug_assert_eq!(patched, 2);
    Ok(out)
}

/// A TZA file with one tensor that claims `dims` of f32 at offset 12 (the file holds 26 bytes).
fn tza_claiming(dims: &[u32]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend(0x41D7u16.to_le_bytes());
    out.extend([2u8, 0]);
    out.extend(12u64.to_le_bytes());
    out.extend(1u32.to_le_bytes());
    let name = b"enc_conv0.weight";
    out.extend((name.len() as u16).to_le_bytes());
    out.extend(name);
    out.push(dims.len() as u8);
    for d in dims {
        out.extend(d.to_le_bytes());
    }
    out.extend(&b"oihw"[..dims.len()]);
    out.push(b'f');
    out.extend(12u64.to_le_bytes());
    out
}

fn make_cases(hush: &Path, dir: &Path) -> Result<Vec<Case>> {
    let f = |name: &str| dir.join(name);
    // A scene file is read by `hush scene check` exactly as `hush render` reads it, without opening the GPU,
    // so the peak memory is the refusal's own.
    let load = |scene: &Path| -> Vec<String> { ["scene", "check", &s(scene)].map(String::from).to_vec() };
    let case = |name, what, args: Vec<String>, expect: &[&str]| Case {
        name,
        what,
        args,
        env: Vec::new(),
        expect: expect.iter().map(|w| w.to_string()).collect(),
        warns: false,
        max_peak_mb: MAX_PEAK_MB,
    };
    let mut cases = Vec::new();

    // A small valid EXR (hush's own render of the box), the base of the image and weight cases.
    let cbox = project_root().join("data/scenes/cbox/scene.xml");
    let small = f("small.exr");
    let status = Command::new(hush)
        .args(["render", &s(&cbox), "--spp", "1", "--width", "16", "--height", "16", "--out", &s(&small)])
        .env("NODEVICE_SELECT", "1")
        .status()
        .map_err(|e| format!("cannot start hush: {e}"))?;
    if !status.success() {
        return Err("hush render of the Cornell box failed: the hostile cases need its small EXR".into());
    }
    let small_bytes = std::fs::read(&small).map_err(|e| format!("{}: {e}", small.display()))?;

    // Scene files.
    sparse(&f("huge.xml"), 3 << 30)?;
    cases.push(case(
        "scene-3gb",
        "a scene file of 3 GB (a hole)",
        load(&f("huge.xml")),
        &["huge.xml", "larger than the limit"],
    ));
    symlink(Path::new("/dev/zero"), &f("zero.xml"))?;
    cases.push(case(
        "scene-dev-zero",
        "a scene file that never ends (/dev/zero)",
        load(&f("zero.xml")),
        &["zero.xml", "not a regular file"],
    ));
    std::fs::create_dir_all(f("folder.xml")).map_err(|e| e.to_string())?;
    cases.push(case(
        "scene-directory",
        "a scene path that is a folder",
        load(&f("folder.xml")),
        &["folder.xml", "is a directory"],
    ));
    symlink(&f("loop-b.xml"), &f("loop-a.xml"))?;
    symlink(&f("loop-a.xml"), &f("loop-b.xml"))?;
    cases.push(case(
        "scene-symlink-loop",
        "a scene path that is a symbolic link loop",
        load(&f("loop-a.xml")),
        &["loop-a.xml", "symbolic link loop"],
    ));
    let nested = "<bsdf type=\"twosided\">".repeat(100_000) + &"</bsdf>".repeat(100_000);
    write(&f("nested.xml"), mitsuba(&format!("<shape type=\"sphere\">{nested}</shape>")))?;
    cases.push(case("mitsuba-nesting", "<bsdf> nested 100,000 deep", load(&f("nested.xml")), &["nested.xml"]));
    let deep = "<a>".repeat(1_000_000) + &"</a>".repeat(1_000_000);
    write(&f("deep.xml"), mitsuba(&deep))?;
    cases.push(case(
        "xml-depth",
        "XML elements nested a million deep",
        load(&f("deep.xml")),
        &["deep.xml", "HUSH_MAX_XML_NODES"],
    ));
    let mut defaults = String::from("<default name=\"v0\" value=\"0123456789\"/>\n");
    for i in 1..40 {
        defaults += &format!("<default name=\"v{i}\" value=\"$v{p}$v{p}\"/>\n", p = i - 1);
    }
    write(
        &f("expand.xml"),
        mitsuba(&format!("{defaults}<shape type=\"sphere\"><float name=\"radius\" value=\"$v39\"/></shape>")),
    )?;
    cases.push(case(
        "mitsuba-expansion",
        "$variables that double 39 times (5 TB)",
        load(&f("expand.xml")),
        &["expand.xml"],
    ));
    write(
        &f("outside.xml"),
        mitsuba(r#"<shape type="obj"><string name="filename" value="../../../../../../etc/hostname"/></shape>"#),
    )?;
    cases.push(case(
        "mesh-outside-folder",
        "a mesh path that leaves the scene's folder",
        load(&f("outside.xml")),
        &["outside.xml", "outside the scene's folder"],
    ));
    std::fs::create_dir_all(f("meshdir.obj")).map_err(|e| e.to_string())?;
    write(&f("mesh-dir.xml"), mitsuba(r#"<shape type="obj"><string name="filename" value="meshdir.obj"/></shape>"#))?;
    cases.push(case(
        "mesh-directory",
        "a mesh path that is a folder",
        load(&f("mesh-dir.xml")),
        &["meshdir.obj", "is a directory"],
    ));
    write(&f("bigtex.png"), png_header(65535, 65535))?;
    write(
        &f("bigtex.xml"),
        mitsuba(
            r#"<shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="bigtex.png"/></texture></bsdf></shape>"#,
        ),
    )?;
    cases.push(Case {
        warns: true,
        ..case(
            "texture-65535",
            "a PNG texture declaring 65535² pixels",
            load(&f("bigtex.xml")),
            &["bigtex.png", "above the limit"],
        )
    });
    symlink(&f("texloop-b.png"), &f("texloop-a.png"))?;
    symlink(&f("texloop-a.png"), &f("texloop-b.png"))?;
    write(
        &f("texloop.xml"),
        mitsuba(
            r#"<shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="texloop-a.png"/></texture></bsdf></shape>"#,
        ),
    )?;
    cases.push(Case {
        warns: true,
        ..case(
            "texture-symlink-loop",
            "a texture that is a symbolic link loop",
            load(&f("texloop.xml")),
            &["texloop-a.png", "symbolic link loop"],
        )
    });

    // OBJ.
    symlink(Path::new("/dev/zero"), &f("zero.mtl"))?;
    write(&f("zero-mtl.obj"), "mtllib zero.mtl\nv 0 0 -2\nv 1 0 -2\nv 0 1 -2\nf 1 2 3\n")?;
    cases.push(Case {
        warns: true,
        ..case(
            "obj-mtl-dev-zero",
            "an OBJ whose material library is /dev/zero",
            load(&f("zero-mtl.obj")),
            &["zero.mtl", "not a regular file"],
        )
    });
    write(&f("bad-index.obj"), "v 0 0 -2\nv 1 0 -2\nv 0 1 -2\nf 1 2 4000000000\n")?;
    cases.push(case(
        "obj-index",
        "an OBJ face with the index 4,000,000,000",
        load(&f("bad-index.obj")),
        &["bad-index.obj"],
    ));

    // glTF.
    let gltf = |extra: &str, accessors: &str| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}{extra}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}}}}]}}],"accessors":[{accessors}]"#
        )
    };
    // A sparse accessor without a buffer view starts from `count` zeros; one sparse value replaces one.
    let sparse_accessor = r#"{"componentType":5126,"count":2147483647,"type":"VEC3","min":[0,0,0],"max":[1,1,1],
"sparse":{"count":1,"indices":{"bufferView":0,"componentType":5125},"values":{"bufferView":1}}}"#;
    write(
        &f("zeros.gltf"),
        gltf("", sparse_accessor)
            + r#","bufferViews":[{"buffer":0,"byteLength":4},{"buffer":0,"byteOffset":4,"byteLength":12}],
"buffers":[{"uri":"data:application/octet-stream;base64,AAAAAAAAgD8AAIA/AACAPw==","byteLength":16}]}"#,
    )?;
    cases.push(case(
        "gltf-2g-zeros",
        "a glTF accessor of 2^31 elements and no data",
        load(&f("zeros.gltf")),
        &["zeros.gltf", "without a buffer view"],
    ));
    let view_accessor = r#"{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,1]}"#;
    write(
        &f("dev-zero.gltf"),
        gltf("", view_accessor)
            + r#","bufferViews":[{"buffer":0,"byteLength":36}],"buffers":[{"uri":"/dev/zero","byteLength":36}]}"#,
    )?;
    cases.push(case(
        "gltf-uri-dev-zero",
        "a glTF buffer at /dev/zero",
        load(&f("dev-zero.gltf")),
        &["dev-zero.gltf", "not a relative path"],
    ));
    write(
        &f("cycle.gltf"),
        gltf(r#",{"children":[2]},{"children":[1]}"#, view_accessor)
            .replace(r#"{"mesh":0}"#, r#"{"mesh":0,"children":[1]}"#)
            + r#","bufferViews":[{"buffer":0,"byteLength":36}],"buffers":[{"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA","byteLength":36}]}"#,
    )?;
    cases.push(case(
        "gltf-node-cycle",
        "glTF nodes that are each other's child",
        load(&f("cycle.gltf")),
        &["cycle.gltf"],
    ));

    // Images.
    write(&f("huge.exr"), patch_exr_size(&small_bytes, 65535)?)?;
    cases.push(case(
        "exr-65535",
        "an EXR declaring 65535² pixels",
        ["denoise", "--color", "huge.exr", "--out", "o.exr"].map(String::from).to_vec(),
        &["huge.exr", "HUSH_MAX_EXR_SAMPLES"],
    ));
    let mut pfm = b"PF\n65535 65535\n-1.0\n".to_vec();
    pfm.extend([0u8; 64]);
    write(&f("huge.pfm"), pfm)?;
    cases.push(case(
        "pfm-65535",
        "a PFM declaring 65535² pixels",
        ["denoise", "--color", "huge.pfm", "--out", "o.pfm"].map(String::from).to_vec(),
        &["huge.pfm", "HUSH_MAX_EXR_SAMPLES"],
    ));

    // Weights.
    let denoise_with = |model: &str| -> Vec<String> {
        ["denoise", "--model", model, "--color", "small.exr", "--out", "o.exr"].map(String::from).to_vec()
    };
    write(&f("huge-tensor.tza"), tza_claiming(&[1 << 20, 1 << 20, 1, 1]))?;
    cases.push(case(
        "tza-2^40-tensor",
        "a TZA tensor of 2^40 floats in a 40-byte file",
        denoise_with("huge-tensor.tza"),
        &["huge-tensor.tza", "runs past the end"],
    ));
    let mut st = (1u64 << 40).to_le_bytes().to_vec();
    st.extend(b"{}");
    write(&f("huge-header.safetensors"), st)?;
    cases.push(case(
        "safetensors-2^40-header",
        "a safetensors header that claims 2^40 bytes",
        denoise_with("huge-header.safetensors"),
        &["huge-header.safetensors"],
    ));
    symlink(Path::new("/dev/zero"), &f("zero.tza"))?;
    cases.push(case(
        "weights-dev-zero",
        "a weight file that never ends (/dev/zero)",
        denoise_with("zero.tza"),
        &["zero.tza", "not a regular file"],
    ));
    sparse(&f("huge.tza"), 3 << 30)?;
    cases.push(case(
        "weights-3gb",
        "a weight file of 3 GB (a hole)",
        denoise_with("huge.tza"),
        &["huge.tza", "HUSH_MAX_WEIGHT_BYTES"],
    ));

    // Manifests.
    std::fs::create_dir_all(f("ds-huge")).map_err(|e| e.to_string())?;
    sparse(&f("ds-huge/manifest.json"), 300 << 20)?;
    let train = |ds: &str| -> Vec<String> {
        ["train", "--dataset", ds, "--out", &format!("run-{ds}"), "--steps", "1"].map(String::from).to_vec()
    };
    cases.push(case(
        "manifest-300mb",
        "a manifest of 300 MB (a hole)",
        train("ds-huge"),
        &["manifest.json", "HUSH_MAX_MANIFEST_BYTES"],
    ));
    std::fs::create_dir_all(f("ds-deep")).map_err(|e| e.to_string())?;
    write(&f("ds-deep/manifest.json"), "[".repeat(1_000_000))?;
    cases.push(case("manifest-depth", "a manifest of a million nested arrays", train("ds-deep"), &["manifest.json"]));

    // The GPU: a render larger than any buffer, against a valid 8² render of the same scene.
    let baseline = gpu_baseline_mb(hush, &cbox, dir)?;
    cases.push(Case {
        max_peak_mb: baseline + GPU_MARGIN_MB,
        ..case(
            "render-32768",
            "a 32768² render (larger than a device buffer)",
            ["render", &s(&cbox), "--spp", "1", "--width", "32768", "--height", "32768", "--out", "big.exr"]
                .map(String::from)
                .to_vec(),
            &["32768", "render a smaller image"],
        )
    });
    Ok(cases)
}
