//! Named optical constants: Mitsuba's conductor `material` names and dielectric IOR names.

use glam::Vec3;

use crate::ComplexIor;

/// RGB complex IORs of the conductors Mitsuba names (`<string name="material" value="Cu"/>`).
///
/// Source: Tungsten's `src/core/bsdfs/ComplexIorData.hpp` (B. Bitterli, github.com/tunabrain/tungsten),
/// the measured spectra Mitsuba ships integrated against linear-sRGB color matching. The shared
/// scenes were exported with these numbers (e.g. veach-mis's plates are its "Cu", living-room's
/// steel is its "Al"). Mitsuba's "none" (a perfect mirror) is handled by the caller. The digits are the
/// source's, kept as printed there so that the table can be checked against it.
#[allow(clippy::excessive_precision)]
const CONDUCTORS: &[(&str, [f32; 3], [f32; 3])] = &[
    ("a-C", [2.9440999183, 2.2271502925, 1.9681668794], [0.8874329109, 0.7993216383, 0.8152862927]),
    ("Ag", [0.1552646489, 0.1167232965, 0.1383806959], [4.8283433224, 3.1222459278, 2.1469504455]),
    ("Al", [1.6574599595, 0.8803689579, 0.5212287346], [9.2238691996, 6.2695232477, 4.8370012281]),
    ("Au", [0.1431189557, 0.3749570432, 1.4424785571], [3.9831604247, 2.3857207478, 1.6032152899]),
    ("Be", [4.1850592788, 3.1850604423, 2.7840913457], [3.8354398268, 3.0101260162, 2.8690088743]),
    ("Cr", [4.3696828663, 2.9167024892, 1.6547005413], [5.2064337956, 4.2313645277, 3.7549467933]),
    ("Cu", [0.2004376970, 0.9240334304, 1.1022119527], [3.9129485033, 2.4528477015, 2.1421879552]),
    ("Cu2O", [3.5492833755, 2.9520622449, 2.7369202137], [0.1132179294, 0.1946659670, 0.6001681264]),
    ("CuO", [3.2453822204, 2.4496293965, 2.1974114493], [0.5202739621, 0.5707372756, 0.7172250613]),
    ("Hg", [2.3989314904, 1.4400254917, 0.9095512090], [6.3276269444, 4.3719414152, 3.4217899270]),
    ("Ir", [3.0864098394, 2.0821938440, 1.6178866805], [5.5921510077, 4.0671757150, 3.2672611269]),
    ("K", [0.0640493070, 0.0464100621, 0.0381842017], [2.1042155920, 1.3489364357, 0.9132113889]),
    ("Li", [0.2657871942, 0.1956102432, 0.2209198538], [3.5401743407, 2.3111306542, 1.6685930000]),
    ("Mo", [4.4837010280, 3.5254578255, 2.7760769438], [4.1111307988, 3.4208716252, 3.1506031404]),
    ("Na", [0.0602665320, 0.0561412435, 0.0619909494], [3.1792906496, 2.1124800781, 1.5790940266]),
    ("Nb", [3.4201353595, 2.7901921379, 2.3955856658], [3.4413817900, 2.7376437930, 2.5799132708]),
    ("Ni", [2.3672753521, 1.6633583302, 1.4670554172], [4.4988329911, 3.0501643957, 2.3454274399]),
    ("Rh", [2.5857954933, 1.8601866068, 1.5544279524], [6.7822927110, 4.7029501026, 3.9760892461]),
    ("Ta", [2.0625846607, 2.3930915569, 2.6280684948], [2.4080467973, 1.7413705864, 1.9470377016]),
    ("TiC", [3.7004673762, 2.8374356509, 2.5823030278], [3.2656905818, 2.3515586388, 2.1727857800]),
    ("TiN", [1.6484691607, 1.1504482522, 1.3797795097], [3.3684596226, 1.9434888540, 1.1020123347]),
    ("V", [4.2775126218, 3.5131538236, 2.7611257461], [3.4911844504, 2.8893580874, 3.1116965117]),
    ("VC", [3.6575665991, 2.7527298065, 2.5326814570], [3.0683516659, 2.1986687713, 1.9631816252]),
    ("VN", [2.8656011588, 2.1191817791, 1.9400767149], [3.0323264950, 2.0561075580, 1.6162930914]),
    ("W", [4.3707029924, 3.3002972445, 2.9982666528], [3.5006778591, 2.6048652781, 2.2731930614]),
];

/// The complex IOR of a named conductor (`"Cu"`, `"Au"`, ...); `None` for an unknown name.
pub(crate) fn conductor(name: &str) -> Option<ComplexIor> {
    CONDUCTORS
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|&(_, eta, k)| ComplexIor { eta: Vec3::from(eta), k: Vec3::from(k) })
}

/// The names [`conductor`] knows, for error messages.
pub(crate) fn conductor_names() -> String {
    CONDUCTORS.iter().map(|c| c.0).collect::<Vec<_>>().join(", ")
}

/// Mitsuba's table of named indices of refraction (documentation of the `dielectric` plugin).
const IORS: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.00004),
    ("hydrogen", 1.00013),
    ("air", 1.00028),
    ("carbon dioxide", 1.00045),
    ("water", 1.3330),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.575),
    ("diamond", 2.419),
];

/// The index of refraction Mitsuba gives a name (`"bk7"`, `"water"`, `"air"`, ...).
pub(crate) fn ior(name: &str) -> Option<f32> {
    IORS.iter().find(|(n, _)| n.eq_ignore_ascii_case(name)).map(|&(_, v)| v)
}

/// The names [`ior`] knows, for error messages.
pub(crate) fn ior_names() -> String {
    IORS.iter().map(|c| c.0).collect::<Vec<_>>().join(", ")
}
