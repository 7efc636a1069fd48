//! The U-Nets' inference pass on x86-64 CPUs with AVX-512, in a blocked channel layout as OIDN's CPU device
//! computes it, with Winograd's F(2×2, 3×3) where OIDN convolves directly.
//!
//! A tensor is stored as blocks of 16 channels, each block `(H + 2) × (W + 2)` pixels of 16 lanes with a
//! zero border ([`Blocked`]), so that a 3×3 window needs no bounds checks and a pixel's 16 channels are
//! one vector.
//!
//! - **One register kernel** ([`kernel`]) keeps `OB × R` output vectors in registers (`OB ≤ 4` blocks of
//!   16 output channels at `R` pixels) and, per input lane, multiplies `OB` weight vectors by the
//!   broadcast input of each pixel: `OB·R` fused multiply-adds per `OB + R` loads, from weights packed
//!   once per network in the order it reads them ([`Packed`]).
//! - **Winograd** ([`conv_winograd`], every layer whose image has even sides): tile rows in parallel; a
//!   task transforms its 4×4 input tiles of every input block (`Bᵀ d B`: additions), runs the kernel as 16
//!   GEMMs over the input channels (one per transformed position, 2.25× fewer multiplications than direct
//!   convolution) and transforms back (`Aᵀ m A`) with the bias and ReLU; where a 2×2 max pooling follows
//!   (each encoder level's last convolution), the 2×2 output tile is the pooling window, so only the
//!   pooled pixel is stored.
//! - **Direct** ([`conv_direct`], odd sides): OIDN's loop order, input blocks outer, accumulating in the
//!   output rows. **Narrow** ([`conv_narrow`]): the 3-channel output layer as per-pixel dot products, not
//!   13 padding channels.
//! - **No copies for the decoder**: the concatenation `[upsampled, skip]` is a list of sources whose
//!   weights are packed to match, and the upsampled source is read from the coarser level ([`Src::Up`])
//!   by the input transform.
//! - **Planned memory** ([`Scratch`]): one arena per network, each tensor placed by a plan made from a
//!   dry run, so that a warm call takes no memory from the system and needs about the largest sum of
//!   tensors alive at once.
//!
//! Every output element is one fixed sequence of operations whatever the thread count, so the result
//! does not depend on it; it differs from the Candle path ([`crate::conv`]) only by f32 rounding (a test
//! bounds the difference). [`crate::UNet`] takes this path for inference on the CPU where the weights
//! record no gradient and [`available`] says the CPU has AVX-512F; `HUSH_DIRECT_CONV=0` turns it off (for
//! comparisons). Training, other CPUs and GPUs keep Candle's path.

use candle_core::{Device, Result, Tensor, bail};

use crate::conv::SharedMut;
use rayon::prelude::*;

/// Channels per block: one AVX-512 vector of f32.
const LANES: usize = 16;

/// Whether [`forward`] can run here: an x86-64 CPU with AVX-512F, and `HUSH_DIRECT_CONV` not `0`.
pub fn available() -> bool {
    static AVAILABLE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *AVAILABLE.get_or_init(|| {
        let off = std::env::var("HUSH_DIRECT_CONV").is_ok_and(|v| v == "0");
        !off && cpu_has_avx512()
    })
}

fn cpu_has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// A `c`-channel `h × w` image in blocks of 16 channels (the last block zero-padded), each block
/// `(h + 2) × (w + 2)` pixels with a zero border: element `((b·(h+2) + y + 1)·(w+2) + x + 1)·16 + l` is
/// channel `16·b + l` at pixel `(y, x)`.
pub(crate) struct Blocked {
    c: usize,
    h: usize,
    w: usize,
    data: Storage,
    /// Which allocation of the call it is ([`Alloc`]).
    id: usize,
}

/// A tensor's memory: a buffer of its own, or its planned place in the scratch arena ([`Alloc`]).
enum Storage {
    Owned(Vec<f32>),
    Arena { ptr: *mut f32, len: usize },
}

// SAFETY: an arena place belongs to one tensor for its whole life (the plan gives tensors alive at the
// same time disjoint places), and the arena is neither moved nor freed while a call's tensors exist.
#[allow(unsafe_code)]
unsafe impl Send for Storage {}
#[allow(unsafe_code)]
unsafe impl Sync for Storage {}

impl std::ops::Deref for Storage {
    type Target = [f32];
    fn deref(&self) -> &[f32] {
        match self {
            Storage::Owned(v) => v,
            // SAFETY: see `unsafe impl Send for Storage`; `ptr..ptr+len` lies inside the arena.
            #[allow(unsafe_code)]
            Storage::Arena { ptr, len } => unsafe { std::slice::from_raw_parts(*ptr, *len) },
        }
    }
}

impl std::ops::DerefMut for Storage {
    fn deref_mut(&mut self) -> &mut [f32] {
        match self {
            Storage::Owned(v) => v,
            // SAFETY: as for `deref`, and only this tensor holds the place.
            #[allow(unsafe_code)]
            Storage::Arena { ptr, len } => unsafe { std::slice::from_raw_parts_mut(*ptr, *len) },
        }
    }
}

impl Blocked {
    /// A tensor whose border is zero and whose interior the caller writes in full before anything reads
    /// it (every output of this module: convolutions, pooling and upsampling write each interior pixel of
    /// every block): no clearing pass over memory that is about to be overwritten.
    fn for_output(c: usize, h: usize, w: usize, scratch: &Alloc) -> Self {
        let (data, id) = scratch.take(c.div_ceil(LANES) * (h + 2) * (w + 2) * LANES);
        let mut t = Blocked { c, h, w, data, id };
        let (row, block) = (t.row_stride(), t.block_stride());
        for b in t.data.chunks_exact_mut(block) {
            b[..row].fill(0.0);
            b[block - row..].fill(0.0);
            for r in b[row..block - row].chunks_exact_mut(row) {
                r[..LANES].fill(0.0);
                r[row - LANES..].fill(0.0);
            }
        }
        t
    }

    /// A placeholder for a tensor already given back (no memory; [`Alloc::give`] ignores it).
    fn empty() -> Self {
        Blocked { c: 0, h: 0, w: 0, data: Storage::Owned(Vec::new()), id: usize::MAX }
    }

    fn blocks(&self) -> usize {
        self.c.div_ceil(LANES)
    }

    fn row_stride(&self) -> usize {
        (self.w + 2) * LANES
    }

    fn block_stride(&self) -> usize {
        (self.h + 2) * self.row_stride()
    }

    /// The offset of pixel `(y, x)` of block `b` in border coordinates (`0..h+2`, `0..w+2`).
    fn at(&self, b: usize, y: usize, x: usize) -> usize {
        pixel_offset((self.h, self.w), b, y, x)
    }

    /// A `c`-channel `h × w` tensor whose interior row `y` of block `b` (`w × 16` values) `fill(b, y, row)`
    /// writes in full; rows in parallel.
    fn from_rows(
        c: usize,
        (w, h): (usize, usize),
        scratch: &Alloc,
        fill: impl Fn(usize, usize, &mut [f32]) + Sync,
    ) -> Self {
        let mut t = Blocked::for_output(c, h, w, scratch);
        if scratch.is_dry() {
            return t;
        }
        let (row, block) = (t.row_stride(), t.block_stride());
        let rows: Vec<(usize, &mut [f32])> = t
            .data
            .chunks_exact_mut(block)
            .flat_map(|b| b[row..block - row].chunks_exact_mut(row).map(|r| &mut r[LANES..row - LANES]))
            .enumerate()
            .collect();
        rows.into_par_iter().for_each(|(i, dst)| fill(i / h, i % h, dst));
        t
    }

    /// A `c`-channel `h × w` tensor whose channel `ch` at pixel `(y, x)` is `value(ch, y, x)`.
    fn from_fn(
        c: usize,
        (w, h): (usize, usize),
        scratch: &Alloc,
        value: impl Fn(usize, usize, usize) -> f32 + Sync,
    ) -> Self {
        Blocked::from_rows(c, (w, h), scratch, |b, y, dst| {
            for (x, px) in dst.chunks_exact_mut(LANES).enumerate() {
                for (l, v) in px.iter_mut().enumerate() {
                    let ch = b * LANES + l;
                    // Lanes past `c` are zero.
                    *v = if ch < c { value(ch, y, x) } else { 0.0 };
                }
            }
        })
    }

    /// From a `c × h × w` (CHW) image.
    fn from_chw(chw: &[f32], c: usize, h: usize, w: usize, scratch: &Alloc) -> Self {
        Blocked::from_fn(c, (w, h), scratch, |ch, y, x| chw[(ch * h + y) * w + x])
    }

    /// From an interleaved `h × w × c` (HWC) image, placed at the top left of a `ph × pw` tensor whose other
    /// pixels are zero.
    fn from_hwc(hwc: &[f32], c: usize, (w, h): (usize, usize), (pw, ph): (usize, usize), scratch: &Alloc) -> Self {
        Blocked::from_fn(c, (pw, ph), scratch, |ch, y, x| if y < h && x < w { hwc[(y * w + x) * c + ch] } else { 0.0 })
    }

    /// The top-left `h × w` pixels of the first `c` channels, interleaved (HWC); rows in parallel.
    fn to_hwc(&self, c: usize, w: usize, h: usize) -> Vec<f32> {
        let mut out = vec![0f32; h * w * c];
        out.par_chunks_mut(w * c).enumerate().for_each(|(y, row)| {
            for (x, px) in row.chunks_mut(c).enumerate() {
                for (ch, v) in px.iter_mut().enumerate() {
                    *v = self.data[self.at(ch / LANES, y + 1, x + 1) + ch % LANES];
                }
            }
        });
        out
    }

    /// The first `c` channels as a `c × h × w` (CHW) image; planes in parallel.
    fn to_chw(&self, c: usize) -> Vec<f32> {
        let (h, w) = (self.h, self.w);
        let mut out = vec![0f32; c * h * w];
        out.par_chunks_mut(h * w).enumerate().for_each(|(ch, plane)| {
            let (b, l) = (ch / LANES, ch % LANES);
            for (y, row) in plane.chunks_mut(w).enumerate() {
                let base = self.at(b, y + 1, 1) + l;
                for (x, v) in row.iter_mut().enumerate() {
                    *v = self.data[base + x * LANES];
                }
            }
        });
        out
    }

    /// 2×2 max pooling (stride 2) of an image with even sides.
    fn max_pool2(&self, scratch: &Alloc) -> Blocked {
        Blocked::from_rows(self.c, (self.w / 2, self.h / 2), scratch, |b, y, row| {
            let w = self.w;
            let top = &self.data[self.at(b, 2 * y + 1, 1)..][..w * LANES];
            let bottom = &self.data[self.at(b, 2 * y + 2, 1)..][..w * LANES];
            for (x, o) in row.chunks_exact_mut(LANES).enumerate() {
                let p = |r: &[f32], dx: usize| -> [f32; LANES] {
                    r[(2 * x + dx) * LANES..][..LANES].try_into().expect("16 lanes")
                };
                let (a, b2, c, d) = (p(top, 0), p(top, 1), p(bottom, 0), p(bottom, 1));
                for (l, v) in o.iter_mut().enumerate() {
                    *v = a[l].max(b2[l]).max(c[l].max(d[l]));
                }
            }
        })
    }

    /// Nearest-neighbour ×2 upsampling.
    fn upsample2(&self, scratch: &Alloc) -> Blocked {
        Blocked::from_rows(self.c, (2 * self.w, 2 * self.h), scratch, |b, y, row| {
            let src = &self.data[self.at(b, y / 2 + 1, 1)..][..self.w * LANES];
            for (x, o) in row.chunks_exact_mut(LANES).enumerate() {
                o.copy_from_slice(&src[(x / 2) * LANES..][..LANES]);
            }
        })
    }
}

/// [`Blocked::at`] of a tensor of `h × w` pixels: the offset of pixel `(y, x)` of block `b` in border
/// coordinates (for tasks that hold only a pointer to the tensor's data).
fn pixel_offset((h, w): (usize, usize), b: usize, y: usize, x: usize) -> usize {
    ((b * (h + 2) + y) * (w + 2) + x) * LANES
}

/// Output blocks per register tile, at most.
const MAX_OB: usize = 4;

/// Pixels per register tile for `ob` output blocks: `ob × R` accumulators of the 32 vector registers, plus
/// `ob` weight vectors and one broadcast.
const fn tile_width(ob: usize) -> usize {
    match ob {
        1 => 24,
        2 => 12,
        3 => 8,
        _ => 6,
    }
}

/// The output blocks `0..blocks` split into groups `(first, count)` of at most [`MAX_OB`], as even as possible
/// (7 blocks: 4 + 3; 5: 3 + 2).
fn groups(blocks: usize) -> Vec<(usize, usize)> {
    let n = blocks.div_ceil(MAX_OB);
    let mut first = 0;
    (0..n)
        .map(|g| {
            let count = blocks / n + usize::from(g < blocks % n);
            let group = (first, count);
            first += count;
            group
        })
        .collect()
}

/// The memory of a network's tensors, kept as long as the network (as an OIDN filter keeps its scratch
/// memory). The first call at an input size first runs the network dry (every operation allocates its
/// output and frees its inputs as it would, computing nothing and holding no memory) and records when each
/// tensor is made and freed; from that record it plans each tensor a place in one arena (tensors alive at
/// the same time apart, largest first at the lowest free offset, as OIDN plans its memory). Every call
/// then runs in the arena: it takes no memory from the system, faults none in after the first, and needs
/// about the largest sum of tensors alive at once. Calls on one network are serialized.
#[derive(Default)]
pub(crate) struct Scratch {
    state: std::sync::Mutex<ScratchState>,
}

#[derive(Default)]
struct ScratchState {
    /// Per input size `(c, h, w)`: each allocation's length and place, in the order a call makes them.
    layouts: std::collections::HashMap<(usize, usize, usize), Layout>,
    arena: Vec<f32>,
}

struct Layout {
    places: Vec<(usize, usize)>,
}

impl std::fmt::Debug for Scratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (sizes, arena) = self.state.lock().map(|s| (s.layouts.len(), s.arena.len())).unwrap_or_default();
        write!(f, "Scratch {{ {sizes} planned size(s), arena {} MiB }}", (arena * 4) >> 20)
    }
}

impl Scratch {
    /// The allocator of one call at input size `key` (waits for another call on the network to finish),
    /// the layout planned first where there is none: `dry` runs the call on a dry allocator.
    fn call(&self, key: (usize, usize, usize), dry: impl FnOnce(&Alloc)) -> Alloc<'_> {
        let state = self.state.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let planned = state.layouts.contains_key(&key);
        let alloc = Alloc {
            state: std::cell::RefCell::new(state),
            key,
            mode: std::cell::RefCell::new(Mode::Dry(Vec::new(), 0)),
        };
        if !planned {
            dry(&alloc);
            let Mode::Dry(events, clock) = alloc.mode.replace(Mode::Planned { next: 0, ok: true }) else {
                unreachable!("the dry run keeps its mode")
            };
            let layout = plan_places(&events, clock);
            let total = layout.places.iter().map(|&(o, l)| o + l).max().unwrap_or(0);
            let mut state = alloc.state.borrow_mut();
            if state.arena.len() < total {
                state.arena = Vec::new();
                state.arena = crate::conv::output_buffer(total);
            }
            state.layouts.insert(key, layout);
        } else {
            alloc.mode.replace(Mode::Planned { next: 0, ok: true });
        }
        alloc
    }
}

/// One call's allocator (see [`Scratch`]).
pub(crate) struct Alloc<'a> {
    state: std::cell::RefCell<std::sync::MutexGuard<'a, ScratchState>>,
    key: (usize, usize, usize),
    mode: std::cell::RefCell<Mode>,
}

enum Mode {
    /// Places from the layout, in order; `ok` until a request differs from the record.
    Planned { next: usize, ok: bool },
    /// The dry run: each allocation's `(length, made at, freed at)` on a clock of events.
    Dry(Vec<(usize, usize, Option<usize>)>, usize),
}

impl Alloc<'_> {
    /// Memory for a tensor of `len` values, which the caller writes before reading (see
    /// [`crate::conv::output_buffer`]), and its allocation id.
    fn take(&self, len: usize) -> (Storage, usize) {
        let mut mode = self.mode.borrow_mut();
        match &mut *mode {
            Mode::Planned { next, ok } => {
                let id = *next;
                *next += 1;
                let mut state = self.state.borrow_mut();
                let place = state.layouts[&self.key].places.get(id).copied();
                match place {
                    Some((offset, planned)) if *ok && planned == len => {
                        // SAFETY: `offset + len` is within the arena, which holds every layout.
                        #[allow(unsafe_code)]
                        let ptr = unsafe { state.arena.as_mut_ptr().add(offset) };
                        (Storage::Arena { ptr, len }, id)
                    }
                    _ => {
                        *ok = false;
                        (Storage::Owned(crate::conv::output_buffer(len)), id)
                    }
                }
            }
            Mode::Dry(events, clock) => {
                events.push((len, *clock, None));
                *clock += 1;
                (Storage::Owned(Vec::new()), events.len() - 1)
            }
        }
    }

    /// Whether this is the dry run: operations return their (empty) outputs at once.
    fn is_dry(&self) -> bool {
        matches!(*self.mode.borrow(), Mode::Dry(..))
    }

    /// Frees a tensor that nothing reads any more.
    fn give(&self, t: Blocked) {
        if let (Mode::Dry(events, clock), true) = (&mut *self.mode.borrow_mut(), t.id != usize::MAX) {
            events[t.id].2 = Some(*clock);
            *clock += 1;
        }
    }

    /// Ends the call; a layout that the call did not follow is forgotten (planned again next time).
    fn finish(self) {
        let mut state = self.state.into_inner();
        if let Mode::Planned { ok: false, .. } = self.mode.into_inner() {
            state.layouts.remove(&self.key);
        }
    }
}

/// Places in one arena for allocations `(length, made at, freed at)`: largest first, each at the lowest
/// offset that overlaps no placed allocation alive at the same time.
fn plan_places(events: &[(usize, usize, Option<usize>)], end: usize) -> Layout {
    let live = |i: usize| (events[i].1, events[i].2.unwrap_or(end + 1));
    let mut order: Vec<usize> = (0..events.len()).collect();
    order.sort_by_key(|&i| (std::cmp::Reverse(events[i].0), events[i].1));
    let mut places = vec![(0usize, 0usize); events.len()];
    let mut placed: Vec<usize> = Vec::new();
    for i in order {
        let (len, (t0, t1)) = (events[i].0, live(i));
        let conflicts: Vec<(usize, usize)> = placed
            .iter()
            .filter(|&&j| {
                let (s0, s1) = live(j);
                s0 < t1 && t0 < s1
            })
            .map(|&j| places[j])
            .collect();
        let fits = |o: usize| conflicts.iter().all(|&(po, pl)| o + len <= po || po + pl <= o);
        let offset = std::iter::once(0)
            .chain(conflicts.iter().map(|&(po, pl)| po + pl))
            .filter(|&o| fits(o))
            .min()
            .expect("the end of the highest placed allocation fits");
        places[i] = (offset, len);
        placed.push(i);
    }
    Layout { places }
}

/// One convolution's weights in the order [`kernel`] reads them, for either algorithm. The output blocks
/// are split into [`groups`]; each group's weights are `[step][input block][input lane][output channel of
/// the group]`, contiguous, where the steps are the 9 taps (direct; the tap inside the input block:
/// `[input block][tap][lane]`) or the 16 transformed positions ξ of Winograd's F(2×2, 3×3). Input channels
/// are laid out block by block over the convolution's sources (a source of 9 channels takes a whole
/// block, its last 7 lanes zero), output channels padded to whole blocks with zero weights and biases.
struct Packed {
    /// Real output channels.
    co: usize,
    in_blocks: usize,
    /// `(first output block, blocks, offset of its weights in data)` per group.
    groups: Vec<(usize, usize, usize)>,
    data: Vec<f32>,
    /// One bias per padded output channel.
    bias: Vec<f32>,
}

/// Winograd's F(2×2, 3×3) (Lavin and Gray 2016): `G`, `Bᵀ` and `Aᵀ` as in [`crate::conv`]'s F2.
const WINO_G: [[f32; 3]; 4] = [[1.0, 0.0, 0.0], [0.5, 0.5, 0.5], [0.5, -0.5, 0.5], [0.0, 0.0, 1.0]];

/// Block and lane of each input channel of the concatenation of sources of `sources[i]` channels: each
/// source starts a block.
fn input_places(sources: &[usize]) -> Vec<(usize, usize)> {
    let mut places = Vec::with_capacity(sources.iter().sum());
    let mut first_block = 0;
    for &c in sources {
        places.extend((0..c).map(|i| (first_block + i / LANES, i % LANES)));
        first_block += c.div_ceil(LANES);
    }
    places
}

impl Packed {
    /// From OIHW `weight` (`co × Σ sources × 3 × 3`) and `bias` (`co`), the input channels split over
    /// sources of `sources[i]` channels in order; transformed by `G g Gᵀ` for Winograd.
    fn new(weight: &[f32], bias: &[f32], co: usize, sources: &[usize], winograd: bool) -> Self {
        let ci: usize = sources.iter().sum();
        let out_blocks = co.div_ceil(LANES);
        let in_blocks: usize = sources.iter().map(|c| c.div_ceil(LANES)).sum();
        let steps = if winograd { 16 } else { 9 };
        let mut data = vec![0f32; steps * in_blocks * LANES * out_blocks * LANES];
        let mut offset = 0;
        let groups: Vec<(usize, usize, usize)> = groups(out_blocks)
            .into_iter()
            .map(|(first, count)| {
                let group = (first, count, offset);
                offset += steps * in_blocks * LANES * count * LANES;
                group
            })
            .collect();
        let places = input_places(sources);
        for &(first, count, offset) in &groups {
            let row = count * LANES;
            for o in first * LANES..(first * LANES + row).min(co) {
                let col = o - first * LANES;
                for (i, &(b, l)) in places.iter().enumerate() {
                    let g = &weight[(o * ci + i) * 9..][..9];
                    if winograd {
                        // u = G g Gᵀ (4 × 4), position ξ = 4·r + c.
                        for (r, gr) in WINO_G.iter().enumerate() {
                            for (c, gc) in WINO_G.iter().enumerate() {
                                let mut u = 0.0;
                                for ky in 0..3 {
                                    for kx in 0..3 {
                                        u += gr[ky] * g[ky * 3 + kx] * gc[kx];
                                    }
                                }
                                data[offset + (((4 * r + c) * in_blocks + b) * LANES + l) * row + col] = u;
                            }
                        }
                    } else {
                        for (tap, &v) in g.iter().enumerate() {
                            data[offset + ((b * 9 + tap) * LANES + l) * row + col] = v;
                        }
                    }
                }
            }
        }
        let mut padded_bias = vec![0f32; out_blocks * LANES];
        padded_bias[..co].copy_from_slice(bias);
        Packed { co, in_blocks, groups, data, bias: padded_bias }
    }
}

/// Output columns per task at most (direct): a task's output rows (`ob` blocks) and one input block's
/// three rows stay in the second level of cache while the kernel runs over the input blocks.
const TASK_COLUMNS: usize = 256;

/// The input blocks of the concatenation of `sources`, in order.
fn input_blocks<'a>(sources: impl IntoIterator<Item = Src<'a>>) -> Vec<InputBlock> {
    sources
        .into_iter()
        .flat_map(|s| match s {
            Src::Full(b) => InputBlock::of(b, false),
            Src::Up(b) => InputBlock::of(b, true),
        })
        .collect()
}

/// The offsets of the 9 taps of a 3×3 window from its top-left pixel, in rows of `row_stride`.
fn taps(row_stride: usize) -> [usize; 9] {
    std::array::from_fn(|t| (t / 3) * row_stride + (t % 3) * LANES)
}

/// A convolution's source: a tensor at the output's size, or one at half the size read upsampled ×2
/// (nearest), as the decoder's first convolutions read the coarser level without storing its upsampling.
#[derive(Clone, Copy)]
pub(crate) enum Src<'a> {
    Full(&'a Blocked),
    Up(&'a Blocked),
}

impl Src<'_> {
    /// Height and width as the convolution sees them.
    fn size(&self) -> (usize, usize) {
        match self {
            Src::Full(b) => (b.h, b.w),
            Src::Up(b) => (2 * b.h, 2 * b.w),
        }
    }
}

/// `relu?(conv3x3(concat(sources)) + bias)` into a new [`Blocked`] of the layer's channels, 2×2
/// max-pooled where `pool` is set (the encoder's levels end so): Winograd's F(2×2, 3×3) where the layer
/// has its weights and the image even sides (its 2×2 output tiles are the pooling windows, so the
/// full-size output is never stored), else direct (upsampled sources then stored first, and the output
/// pooled after).
fn conv(sources: &[Src], layer: &Layer, relu: bool, pool: bool, scratch: &Alloc) -> Blocked {
    let (h, w) = sources[0].size();
    debug_assert!(sources.iter().all(|s| s.size() == (h, w)));
    match (&layer.winograd, &layer.narrow) {
        (Some(packed), None) if h % 2 == 0 && w % 2 == 0 => conv_winograd(sources, packed, relu, pool, scratch),
        _ if pool => {
            let full = conv(sources, layer, relu, false, scratch);
            let pooled = full.max_pool2(scratch);
            scratch.give(full);
            pooled
        }
        _ => {
            let ups: Vec<Blocked> = sources
                .iter()
                .filter_map(|s| if let Src::Up(b) = s { Some(b.upsample2(scratch)) } else { None })
                .collect();
            let mut stored = ups.iter();
            let full: Vec<&Blocked> = sources
                .iter()
                .map(|s| match s {
                    Src::Full(b) => b,
                    Src::Up(_) => stored.next().expect("one per upsampled source"),
                })
                .collect();
            let out = match &layer.narrow {
                Some(narrow) => conv_narrow(&full, narrow, relu, scratch),
                None => conv_direct(&full, layer.direct(), relu, scratch),
            };
            ups.into_iter().for_each(|u| scratch.give(u));
            out
        }
    }
}

/// [`conv`] by direct convolution. Tasks are (output row, column range, group of output blocks); each
/// runs over the input blocks in order, every tile of its columns per input block, accumulating in its
/// output rows (the bias first, the ReLU after the last block), as OIDN's CPU convolution does.
fn conv_direct(sources: &[&Blocked], packed: &Packed, relu: bool, scratch: &Alloc) -> Blocked {
    let (h, w) = (sources[0].h, sources[0].w);
    let mut out = Blocked::for_output(packed.co, h, w, scratch);
    if scratch.is_dry() {
        return out;
    }
    let dst = SharedMut(out.data.as_mut_ptr());
    let out_block_stride = out.block_stride();
    let blocks = input_blocks(sources.iter().map(|s| Src::Full(s)));
    debug_assert_eq!(blocks.len(), packed.in_blocks);
    let row_stride = sources[0].row_stride();
    let taps = taps(row_stride);
    let column_tiles = w.div_ceil(TASK_COLUMNS);
    let per_tile = w.div_ceil(column_tiles);
    let tasks = h * column_tiles * packed.groups.len();
    (0..tasks).into_par_iter().for_each(|task| {
        let (g, rest) = (task % packed.groups.len(), task / packed.groups.len());
        let (y, ct) = (rest / column_tiles, rest % column_tiles);
        let (x0, x1) = (ct * per_tile, ((ct + 1) * per_tile).min(w));
        let (first, ob, offset) = packed.groups[g];
        let step = tile_width(ob);
        let weights_per_block = 9 * LANES * ob * LANES;
        for (ib, block) in blocks.iter().enumerate() {
            let mut x = x0;
            while x < x1 {
                let r = step.min(x1 - x);
                let tile = Tile {
                    // Output (y, x) reads border rows y..y+3 and columns x..x+3.
                    input: block.0.wrapping_add(y * row_stride + x * LANES),
                    in_pixel: LANES,
                    steps: &taps,
                    weights: packed.data[offset + ib * weights_per_block..].as_ptr(),
                    init: if ib == 0 { Init::Bias(packed.bias[first * LANES..].as_ptr()) } else { Init::Load },
                    out: dst.get().wrapping_add(pixel_offset((h, w), first, y + 1, x + 1)),
                    out_pixel: LANES,
                    out_block: out_block_stride,
                    relu: relu && ib + 1 == blocks.len(),
                };
                // SAFETY: `tile` reads rows y..y+3, columns x..x+r+2 of one input block (inside it: its
                // border makes that window exist), that block's weights of the group (`9·16` rows of
                // `ob·16`), and reads and writes `ob` output blocks at row y, columns x..x+r, which only
                // this task touches (tasks split rows, columns and output blocks).
                #[allow(unsafe_code)]
                unsafe {
                    run_tile(&tile, ob, r)
                };
                x += r;
            }
        }
    });
    out
}

/// Tiles (of 2×2 output pixels) per Winograd task: the task's transformed input (`16 × blocks × tiles`
/// vectors) and products (`16 × tiles × ob` vectors) stay in the second level of cache.
const WINO_TILES: usize = 32;

/// Floats per transformed tile of one block in a Winograd task's buffers: 16 vectors, plus one so that
/// the same position of neighbouring tiles does not fall into the same few sets of the first-level cache.
const TILE_STRIDE: usize = 17 * LANES;

/// [`conv`] by Winograd's F(2×2, 3×3): 2.25× fewer multiplications than direct convolution. Tasks are
/// (tile row, range of tiles). A task transforms its input tiles of every input block once (`Bᵀ d B`,
/// additions only), then per group of output blocks computes the 16 products of the transformed weights
/// and inputs summed over input channels (a GEMM per position ξ, by the same register [`kernel`]), and
/// transforms them back (`Aᵀ m A`), adding the bias and applying the ReLU as it stores the output.
fn conv_winograd(sources: &[Src], packed: &Packed, relu: bool, pool: bool, scratch: &Alloc) -> Blocked {
    let (h, w) = sources[0].size();
    debug_assert!(h % 2 == 0 && w % 2 == 0);
    // Pooled, a tile is one output pixel.
    let (oh, ow, px) = if pool { (h / 2, w / 2, 1) } else { (h, w, 2) };
    let mut out = Blocked::for_output(packed.co, oh, ow, scratch);
    if scratch.is_dry() {
        return out;
    }
    let dst = SharedMut(out.data.as_mut_ptr());
    let out_row_stride = out.row_stride();
    let blocks = input_blocks(sources.iter().copied());
    let nb = blocks.len();
    debug_assert_eq!(nb, packed.in_blocks);
    let (tiles_y, tiles_x) = (h / 2, w / 2);
    let segments = tiles_x.div_ceil(WINO_TILES);
    let per_segment = tiles_x.div_ceil(segments);
    (0..tiles_y * segments).into_par_iter().for_each_init(
        || (Vec::<f32>::new(), Vec::<f32>::new()),
        |(v, m), task| {
            let (ty, sg) = (task / segments, task % segments);
            let (t0, t1) = (sg * per_segment, ((sg + 1) * per_segment).min(tiles_x));
            let nt = t1 - t0;
            // V[block][tile][ξ][lane]: each tile's 16 transformed vectors contiguous ([`TILE_STRIDE`]).
            v.resize(nb * nt * TILE_STRIDE, 0.0);
            for (b, &InputBlock(data, rs, up)) in blocks.iter().enumerate() {
                // The tile's input rows and columns: border rows 2ty..2ty+4 (columns likewise) or, read
                // upsampled, rows ty, ty+1, ty+1, ty+2 of the half-size source (border coordinates: the
                // full-size row r − 1 is the half-size row (r − 1) div 2, and both borders are zero).
                let (step, rows, cols) = if up {
                    (1, [0, rs, rs, 2 * rs], [0, LANES, LANES, 2 * LANES])
                } else {
                    (2, [0, rs, 2 * rs, 3 * rs], [0, LANES, 2 * LANES, 3 * LANES])
                };
                for t in 0..nt {
                    // SAFETY: the input tile lies inside the block (its border); the 16 destination
                    // vectors lie inside `v`.
                    #[allow(unsafe_code)]
                    unsafe {
                        input_transform(
                            data.add(step * (ty * rs + (t0 + t) * LANES)),
                            &rows,
                            &cols,
                            v.as_mut_ptr().add((b * nt + t) * TILE_STRIDE),
                        )
                    };
                }
            }
            let steps: Vec<usize> = (0..nb).map(|b| b * nt * TILE_STRIDE).collect();
            for &(first, ob, offset) in &packed.groups {
                // M[tile][block o][ξ][lane], a tile's blocks TILE_STRIDE apart.
                m.resize(nt * ob * TILE_STRIDE, 0.0);
                let step = tile_width(ob);
                for xi in 0..16 {
                    let mut p = 0;
                    while p < nt {
                        let r = step.min(nt - p);
                        let tile = Tile {
                            input: v[p * TILE_STRIDE + xi * LANES..].as_ptr(),
                            in_pixel: TILE_STRIDE,
                            steps: &steps,
                            weights: packed.data[offset + xi * nb * LANES * ob * LANES..].as_ptr(),
                            init: Init::Zero,
                            out: m[p * ob * TILE_STRIDE + xi * LANES..].as_mut_ptr(),
                            out_pixel: ob * TILE_STRIDE,
                            out_block: TILE_STRIDE,
                            relu: false,
                        };
                        // SAFETY: the tile reads `r` tiles' position ξ of every block b (inside `v`),
                        // the group's weights of position ξ (`nb·16` rows of `ob·16`) and writes `r` tiles'
                        // position ξ of M (inside `m`, owned by this task).
                        #[allow(unsafe_code)]
                        unsafe {
                            run_tile(&tile, ob, r)
                        };
                        p += r;
                    }
                }
                for t in 0..nt {
                    for o in 0..ob {
                        // SAFETY: reads the 16 vectors of M at tile t, block o (inside `m`) and writes the
                        // 2×2 output pixels (pooled: the one pixel) of tile (ty, t0+t) of output block
                        // first+o, inside `out` and written by this task only.
                        #[allow(unsafe_code)]
                        unsafe {
                            output_transform(
                                m.as_ptr().add((t * ob + o) * TILE_STRIDE),
                                packed.bias[(first + o) * LANES..].as_ptr(),
                                dst.get().add(pixel_offset((oh, ow), first + o, px * ty + 1, px * (t0 + t) + 1)),
                                out_row_stride,
                                (relu, pool),
                            )
                        };
                    }
                }
            }
        },
    );
    out
}

/// `Bᵀ d B` of the 4×4 input tile `d[r][c] = src[rows[r] + cols[c]]` (16 lanes each) into the 16 vectors
/// `dst + 16·ξ`, `ξ = 4·r + c`.
///
/// # Safety
/// AVX-512F; the tile and the destinations must be valid.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
#[target_feature(enable = "avx512f")]
#[allow(clippy::needless_range_loop)] // register tiles: indices into fixed arrays of vectors
unsafe fn input_transform(src: *const f32, rows: &[usize; 4], cols: &[usize; 4], dst: *mut f32) {
    use std::arch::x86_64::*;
    // SAFETY: the caller's contract.
    unsafe {
        let d: [[__m512; 4]; 4] =
            std::array::from_fn(|r| std::array::from_fn(|c| _mm512_loadu_ps(src.add(rows[r] + cols[c]))));
        // Bᵀ d: rows d0 − d2, d1 + d2, d2 − d1, d1 − d3.
        let t: [[__m512; 4]; 4] = std::array::from_fn(|c| {
            [
                _mm512_sub_ps(d[0][c], d[2][c]),
                _mm512_add_ps(d[1][c], d[2][c]),
                _mm512_sub_ps(d[2][c], d[1][c]),
                _mm512_sub_ps(d[1][c], d[3][c]),
            ]
        });
        // (Bᵀ d) B: the same along the columns; t[c][r] is row r, column c of Bᵀ d.
        for r in 0..4 {
            let v = [
                _mm512_sub_ps(t[0][r], t[2][r]),
                _mm512_add_ps(t[1][r], t[2][r]),
                _mm512_sub_ps(t[2][r], t[1][r]),
                _mm512_sub_ps(t[1][r], t[3][r]),
            ];
            for (c, &x) in v.iter().enumerate() {
                _mm512_storeu_ps(dst.add((4 * r + c) * LANES), x);
            }
        }
    }
}

/// `Aᵀ m A + bias` (ReLU'd if asked) of the 16 vectors `m + 16·ξ` into the 2×2 output pixels at
/// `dst` (rows `row_stride` apart), or with `pool` their maximum into the one pixel at `dst`.
///
/// # Safety
/// AVX-512F; the sources and the destination pixels must be valid.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
#[target_feature(enable = "avx512f")]
#[allow(clippy::needless_range_loop)] // register tiles: indices into fixed arrays of vectors
unsafe fn output_transform(
    m: *const f32,
    bias: *const f32,
    dst: *mut f32,
    row_stride: usize,
    (relu, pool): (bool, bool),
) {
    use std::arch::x86_64::*;
    // SAFETY: the caller's contract.
    unsafe {
        let v: [[__m512; 4]; 4] =
            std::array::from_fn(|r| std::array::from_fn(|c| _mm512_loadu_ps(m.add((4 * r + c) * LANES))));
        // Aᵀ m: rows m0 + m1 + m2 and m1 − m2 − m3.
        let s: [[__m512; 4]; 2] = [
            std::array::from_fn(|c| _mm512_add_ps(_mm512_add_ps(v[0][c], v[1][c]), v[2][c])),
            std::array::from_fn(|c| _mm512_sub_ps(_mm512_sub_ps(v[1][c], v[2][c]), v[3][c])),
        ];
        let b = _mm512_loadu_ps(bias);
        let zero = _mm512_setzero_ps();
        let y: [[__m512; 2]; 2] = std::array::from_fn(|i| {
            let si = &s[i];
            let y = [
                _mm512_add_ps(_mm512_add_ps(_mm512_add_ps(si[0], si[1]), si[2]), b),
                _mm512_add_ps(_mm512_sub_ps(_mm512_sub_ps(si[1], si[2]), si[3]), b),
            ];
            y.map(|v| if relu { _mm512_max_ps(v, zero) } else { v })
        });
        if pool {
            let m = _mm512_max_ps(_mm512_max_ps(y[0][0], y[0][1]), _mm512_max_ps(y[1][0], y[1][1]));
            _mm512_storeu_ps(dst, m);
        } else {
            for (i, yi) in y.iter().enumerate() {
                for (j, &yj) in yi.iter().enumerate() {
                    _mm512_storeu_ps(dst.add(i * row_stride + j * LANES), yj);
                }
            }
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[allow(unsafe_code)]
unsafe fn input_transform(_: *const f32, _: &[usize; 4], _: &[usize; 4], _: *mut f32) {
    unreachable!("direct convolutions run only where `available` is true")
}

#[cfg(not(target_arch = "x86_64"))]
#[allow(unsafe_code)]
unsafe fn output_transform(_: *const f32, _: *const f32, _: *mut f32, _: usize, _: (bool, bool)) {
    unreachable!("direct convolutions run only where `available` is true")
}

/// Output channels up to which a convolution takes [`conv_narrow`].
const NARROW_MAX: usize = 3;

/// Pixels per register tile of [`narrow_kernel`]: `co × 8` accumulators.
const NARROW_PIXELS: usize = 8;

/// A convolution to at most [`NARROW_MAX`] channels (the output layer: 3), whose output block would be
/// mostly padding in [`conv_direct`]: weights `[input block][tap][output channel][input lane]`.
struct Narrow {
    co: usize,
    data: Vec<f32>,
    bias: Vec<f32>,
}

impl Narrow {
    fn new(weight: &[f32], bias: &[f32], co: usize, sources: &[usize]) -> Self {
        let ci: usize = sources.iter().sum();
        let in_blocks: usize = sources.iter().map(|c| c.div_ceil(LANES)).sum();
        let mut data = vec![0f32; in_blocks * 9 * co * LANES];
        for (i, (b, l)) in input_places(sources).into_iter().enumerate() {
            for o in 0..co {
                for tap in 0..9 {
                    data[((b * 9 + tap) * co + o) * LANES + l] = weight[(o * ci + i) * 9 + tap];
                }
            }
        }
        Narrow { co, data, bias: bias.to_vec() }
    }
}

/// [`conv`] to at most [`NARROW_MAX`] channels: each pixel's output channel is a dot product of the
/// 16-lane input vectors and weight vectors of every input block and tap, reduced across lanes at the end
/// (a multiply-add per 16 real products, where [`conv_direct`] would spend one per 16 lanes of which
/// `16 − co` are padding).
fn conv_narrow(sources: &[&Blocked], narrow: &Narrow, relu: bool, scratch: &Alloc) -> Blocked {
    let (h, w) = (sources[0].h, sources[0].w);
    let mut out = Blocked::for_output(narrow.co, h, w, scratch);
    if scratch.is_dry() {
        return out;
    }
    let dst = SharedMut(out.data.as_mut_ptr());
    let blocks = input_blocks(sources.iter().map(|s| Src::Full(s)));
    let row_stride = sources[0].row_stride();
    let taps = taps(row_stride);
    (0..h).into_par_iter().for_each(|y| {
        let mut x = 0;
        while x < w {
            let r = NARROW_PIXELS.min(w - x);
            let tile = NarrowTile {
                blocks: &blocks,
                input: y * row_stride + x * LANES,
                taps: &taps,
                weights: narrow.data.as_ptr(),
                bias: &narrow.bias,
                out: dst.get().wrapping_add(pixel_offset((h, w), 0, y + 1, x + 1)),
                relu,
            };
            // SAFETY: reads rows y..y+3, columns x..x+r+2 of every input block (inside: the border), the
            // packed weights (`blocks × 9 × co` vectors) and writes `r` pixels of row y of the output's one
            // block, touched by this task (row) only.
            #[allow(unsafe_code)]
            unsafe {
                run_narrow(&tile, narrow.co, r)
            };
            x += r;
        }
    });
    out
}

/// One register tile of [`conv_narrow`].
struct NarrowTile<'a> {
    blocks: &'a [InputBlock],
    /// Offset of the window's top-left pixel in every input block.
    input: usize,
    taps: &'a [usize; 9],
    weights: *const f32,
    bias: &'a [f32],
    out: *mut f32,
    relu: bool,
}

/// Runs [`narrow_kernel`] for `co` channels and `r ≤ NARROW_PIXELS` pixels.
///
/// # Safety
/// See the call in [`conv_narrow`].
#[allow(unsafe_code)]
unsafe fn run_narrow(t: &NarrowTile, co: usize, r: usize) {
    macro_rules! dispatch {
        ($co:literal) => {
            match r {
                1 => narrow_kernel::<$co, 1>(t),
                2 => narrow_kernel::<$co, 2>(t),
                3 => narrow_kernel::<$co, 3>(t),
                4 => narrow_kernel::<$co, 4>(t),
                5 => narrow_kernel::<$co, 5>(t),
                6 => narrow_kernel::<$co, 6>(t),
                7 => narrow_kernel::<$co, 7>(t),
                8 => narrow_kernel::<$co, 8>(t),
                _ => unreachable!("tile width {r}"),
            }
        };
    }
    // SAFETY: forwarded; the CPU has AVX-512F (`available`).
    unsafe {
        match co {
            1 => dispatch!(1),
            2 => dispatch!(2),
            _ => dispatch!(3),
        }
    }
}

/// `C` output channels at `P` pixels of [`NarrowTile`].
///
/// # Safety
/// AVX-512F, and the tile's addresses valid (see [`conv_narrow`]).
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
#[target_feature(enable = "avx512f")]
#[allow(clippy::needless_range_loop)] // register tiles: indices into fixed arrays of vectors
unsafe fn narrow_kernel<const C: usize, const P: usize>(t: &NarrowTile) {
    use std::arch::x86_64::*;
    // SAFETY: the caller's contract.
    unsafe {
        let mut acc = [[_mm512_setzero_ps(); P]; C];
        let mut wrow = t.weights;
        for block in t.blocks {
            for &tap in t.taps {
                let ip = block.0.add(t.input + tap);
                let wv: [__m512; C] = std::array::from_fn(|o| _mm512_loadu_ps(wrow.add(o * LANES)));
                for p in 0..P {
                    let x = _mm512_loadu_ps(ip.add(p * LANES));
                    for o in 0..C {
                        acc[o][p] = _mm512_fmadd_ps(wv[o], x, acc[o][p]);
                    }
                }
                wrow = wrow.add(C * LANES);
            }
        }
        for p in 0..P {
            let mut v = [0f32; LANES];
            for o in 0..C {
                let y = _mm512_reduce_add_ps(acc[o][p]) + t.bias[o];
                v[o] = if t.relu { y.max(0.0) } else { y };
            }
            _mm512_storeu_ps(t.out.add(p * LANES), _mm512_loadu_ps(v.as_ptr()));
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[allow(unsafe_code)]
unsafe fn narrow_kernel<const C: usize, const P: usize>(_: &NarrowTile) {
    unreachable!("direct convolutions run only where `available` is true")
}

/// One input block of a convolution: a pointer into its source (which outlives the convolution), the
/// source's row stride, and whether it is read upsampled.
struct InputBlock(*const f32, usize, bool);

impl InputBlock {
    fn of(s: &Blocked, up: bool) -> impl Iterator<Item = InputBlock> + '_ {
        (0..s.blocks()).map(move |b| InputBlock(s.data[b * s.block_stride()..].as_ptr(), s.row_stride(), up))
    }
}
// SAFETY: read-only views of buffers that outlive the convolution.
#[allow(unsafe_code)]
unsafe impl Send for InputBlock {}
#[allow(unsafe_code)]
unsafe impl Sync for InputBlock {}

/// How a register tile's accumulators start.
#[derive(Clone, Copy)]
enum Init {
    Zero,
    /// From the group's biases.
    Bias(*const f32),
    /// From the output (a partial sum over earlier input blocks).
    Load,
}

/// One register tile: `ob` output blocks at `r` pixels, a sum over `steps.len() × 16` inputs: for step `k`
/// and lane `l`, pixel `p` reads `input[steps[k] + in_pixel·p + l]` and multiplies it by the weight row `16·k + l`
/// (`ob·16` output channels, rows contiguous from `weights`).
struct Tile<'a> {
    input: *const f32,
    /// Floats between neighbouring pixels of the input.
    in_pixel: usize,
    steps: &'a [usize],
    weights: *const f32,
    init: Init,
    /// Output block `o` of pixel `p` is the 16 floats at `out + p·out_pixel + o·out_block`.
    out: *mut f32,
    out_pixel: usize,
    out_block: usize,
    /// Apply the ReLU before storing.
    relu: bool,
}

/// Runs [`kernel`] for `ob` blocks and `r ≤ tile_width(ob)` pixels.
///
/// # Safety
/// See the calls in [`conv_direct`] and [`conv_winograd`].
#[allow(unsafe_code)]
unsafe fn run_tile(t: &Tile, ob: usize, r: usize) {
    macro_rules! dispatch {
        ($ob:literal; $($r:literal)*) => {
            match r {
                $($r => kernel::<$ob, $r>(t),)*
                _ => unreachable!("tile width {r}"),
            }
        };
    }
    // SAFETY: forwarded; the CPU has AVX-512F (`available`).
    unsafe {
        match ob {
            1 => dispatch!(1; 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24),
            2 => dispatch!(2; 1 2 3 4 5 6 7 8 9 10 11 12),
            3 => dispatch!(3; 1 2 3 4 5 6 7 8),
            _ => dispatch!(4; 1 2 3 4 5 6),
        }
    }
}

/// The register tile of [`Tile`]: `B` output blocks at `P` pixels.
///
/// # Safety
/// The CPU must have AVX-512F, and the tile's addresses must be valid.
#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
#[target_feature(enable = "avx512f")]
#[allow(clippy::needless_range_loop)] // register tiles: indices into fixed arrays of vectors
unsafe fn kernel<const B: usize, const P: usize>(t: &Tile) {
    use std::arch::x86_64::*;
    // SAFETY: the caller's contract.
    unsafe {
        let mut acc = [[_mm512_setzero_ps(); P]; B];
        for (o, acc_o) in acc.iter_mut().enumerate() {
            match t.init {
                Init::Zero => {}
                Init::Bias(bias) => acc_o.fill(_mm512_loadu_ps(bias.add(o * LANES))),
                Init::Load => {
                    for (p, a) in acc_o.iter_mut().enumerate() {
                        *a = _mm512_loadu_ps(t.out.add(p * t.out_pixel + o * t.out_block));
                    }
                }
            }
        }
        let mut wrow = t.weights;
        for &step in t.steps {
            let ip = t.input.add(step);
            for l in 0..LANES {
                let wv: [__m512; B] = std::array::from_fn(|o| _mm512_loadu_ps(wrow.add(o * LANES)));
                for p in 0..P {
                    let v = _mm512_set1_ps(*ip.add(p * t.in_pixel + l));
                    for o in 0..B {
                        acc[o][p] = _mm512_fmadd_ps(wv[o], v, acc[o][p]);
                    }
                }
                wrow = wrow.add(B * LANES);
            }
        }
        let zero = _mm512_setzero_ps();
        for (o, acc_o) in acc.iter().enumerate() {
            for (p, &a) in acc_o.iter().enumerate() {
                let a = if t.relu { _mm512_max_ps(a, zero) } else { a };
                _mm512_storeu_ps(t.out.add(p * t.out_pixel + o * t.out_block), a);
            }
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
#[allow(unsafe_code)]
unsafe fn kernel<const B: usize, const P: usize>(_: &Tile) {
    unreachable!("direct convolutions run only where `available` is true")
}

/// One convolution of a network: its packed weights.
pub(crate) struct Layer {
    co: usize,
    /// The OIHW weights and biases (the network's own tensors), packed for the direct path on first
    /// need (an image whose side at this layer is odd): most layers never need it.
    weight: Tensor,
    bias: Tensor,
    sources: Vec<usize>,
    direct: std::sync::OnceLock<Packed>,
    /// For images of even sides.
    winograd: Option<Packed>,
    /// For outputs of at most [`NARROW_MAX`] channels.
    narrow: Option<Narrow>,
}

impl Layer {
    /// From OIHW `weight` and `bias` tensors (any device, f32), the input channels split over sources of
    /// `sources[i]` channels.
    pub(crate) fn new(weight: &Tensor, bias: &Tensor, sources: &[usize]) -> Result<Self> {
        let (co, ci, kh, kw) = weight.dims4()?;
        if (kh, kw) != (3, 3) || ci != sources.iter().sum::<usize>() || bias.dims1()? != co {
            bail!("direct conv: weight {:?} and bias {:?} do not fit sources {sources:?}", weight.dims(), bias.dims())
        }
        let w = weight.flatten_all()?.to_vec1::<f32>()?;
        let b = bias.to_vec1::<f32>()?;
        // Winograd unless the output is one block (the 3-channel output layer: its 13 padding channels
        // would be transformed too).
        let winograd = (co > LANES).then(|| Packed::new(&w, &b, co, sources, true));
        let narrow = (co <= NARROW_MAX).then(|| Narrow::new(&w, &b, co, sources));
        let (weight, bias, sources) = (weight.clone(), bias.clone(), sources.to_vec());
        Ok(Layer { co, weight, bias, sources, direct: Default::default(), winograd, narrow })
    }

    /// The weights packed for [`conv_direct`].
    fn direct(&self) -> &Packed {
        self.direct.get_or_init(|| {
            // `new` read both tensors as f32 already.
            let w = self.weight.flatten_all().and_then(|t| t.to_vec1::<f32>()).expect("f32 weights");
            let b = self.bias.to_vec1::<f32>().expect("f32 biases");
            Packed::new(&w, &b, self.co, &self.sources, false)
        })
    }
}

/// The layers of a U-Net in [`crate::UNet`]'s order, with the levels' structure, packed.
pub(crate) struct Plan {
    /// Per encoder level; levels 0–3 end in a 2×2 max pooling.
    pub enc: Vec<Vec<Layer>>,
    /// Per decoder level, coarsest first; each starts with an upsampling and, with `skips`, the
    /// concatenation `[upsampled, skip]`.
    pub dec: Vec<Vec<Layer>>,
    pub out: Layer,
    pub skips: bool,
}

/// The network of `plan` on an input whose sides are multiples of 16. Each tensor's buffer goes back to
/// `scratch` as soon as nothing reads it any more.
fn forward_blocked(plan: &Plan, scratch: &Alloc, input: Blocked) -> Blocked {
    // skips = [input, pool1, pool2, pool3]; `x` is None while the current tensor is the last skip.
    let mut skips = vec![input];
    let mut x: Option<Blocked> = None;
    for (level, layers) in plan.enc.iter().enumerate() {
        for (i, layer) in layers.iter().enumerate() {
            let cur = x.as_ref().unwrap_or_else(|| skips.last().expect("the input"));
            // Levels 0–3 end in a pooling, done by their last convolution.
            let pool = level < 4 && i + 1 == layers.len();
            let y = conv(&[Src::Full(cur)], layer, true, pool, scratch);
            if let Some(old) = x.replace(y) {
                scratch.give(old);
            }
        }
        if level < 4 {
            let pooled = x.take().expect("every level has a convolution");
            if level < 3 {
                skips.push(pooled);
            } else {
                x = Some(pooled);
            }
        }
    }
    for layers in &plan.dec {
        let mut skip = skips.pop().expect("one skip per decoder level");
        let mut low = x.take().expect("the decoder's input");
        let mut cur: Option<Blocked> = None;
        for (i, layer) in layers.iter().enumerate() {
            let y = match (&cur, i == 0 && plan.skips) {
                (None, true) => conv(&[Src::Up(&low), Src::Full(&skip)], layer, true, false, scratch),
                (None, false) => conv(&[Src::Up(&low)], layer, true, false, scratch),
                (Some(c), _) => conv(&[Src::Full(c)], layer, true, false, scratch),
            };
            if let Some(old) = cur.replace(y) {
                scratch.give(old);
            }
            if i == 0 {
                // Only the level's first convolution reads them.
                scratch.give(std::mem::replace(&mut low, Blocked::empty()));
                scratch.give(std::mem::replace(&mut skip, Blocked::empty()));
            }
        }
        x = cur;
    }
    let last = x.expect("the decoder's output");
    let y = conv(&[Src::Full(&last)], &plan.out, false, false, scratch);
    scratch.give(last);
    y
}

/// The network of `plan` on a CHW image whose sides are multiples of 16; the output is `co × h × w`.
pub(crate) fn forward(plan: &Plan, scratch: &Scratch, image: &[f32], (c, h, w): (usize, usize, usize)) -> Vec<f32> {
    let alloc =
        scratch.call((c, h, w), |dry| dry.give(forward_blocked(plan, dry, Blocked::from_chw(image, c, h, w, dry))));
    let y = forward_blocked(plan, &alloc, Blocked::from_chw(image, c, h, w, &alloc));
    let out = y.to_chw(plan.out.co);
    alloc.give(y);
    alloc.finish();
    out
}

/// The network of `plan` on an interleaved `height × width × c` image of any size, zero-padded at the
/// bottom and right to multiples of 16 (as OIDN pads a tile), which it drops once it is read; the output
/// interleaved `height × width × co`, the padding cropped.
pub(crate) fn forward_hwc(plan: &Plan, scratch: &Scratch, hwc: Vec<f32>, (w, h, c): (usize, usize, usize)) -> Vec<f32> {
    let align = |n: usize| n.div_ceil(16).max(1) * 16;
    let (pw, ph) = (align(w), align(h));
    let alloc = scratch.call((c, ph, pw), |dry| {
        dry.give(forward_blocked(plan, dry, Blocked::from_hwc(&hwc, c, (w, h), (pw, ph), dry)))
    });
    let input = Blocked::from_hwc(&hwc, c, (w, h), (pw, ph), &alloc);
    drop(hwc);
    let y = forward_blocked(plan, &alloc, input);
    let out = y.to_hwc(plan.out.co, w, h);
    alloc.give(y);
    alloc.finish();
    out
}

/// [`forward`] on every image of an NCHW f32 CPU tensor.
pub(crate) fn forward_tensor(plan: &Plan, scratch: &Scratch, x: &Tensor) -> Result<Tensor> {
    let (n, c, h, w) = x.dims4()?;
    let data = x.flatten_all()?.to_vec1::<f32>()?;
    let co = plan.out.co;
    let mut out = Vec::with_capacity(n * co * h * w);
    for image in data.chunks(c * h * w) {
        out.extend(forward(plan, scratch, image, (c, h, w)));
    }
    Tensor::from_vec(out, (n, co, h, w), &Device::Cpu)
}
