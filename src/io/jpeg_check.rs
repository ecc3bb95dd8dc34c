//! Does a JPEG hold all its data? A decoder that reaches the end of the compressed data early (a file cut short
//! with an end marker added) or never finds the end (a zero-filled tail: a preallocated file, a power cut) fills
//! the rest with grey or with garbage and reports success; zune-jpeg does so even in strict mode. [`check`] walks
//! the markers and, for baseline (sequential Huffman) JPEGs, Huffman-decodes every scan without the inverse DCT,
//! counting blocks: each scan must hold every MCU of the frame (with every restart marker in place) within its
//! own data, and an end-of-image marker must follow the last scan. Progressive and other JPEGs get the marker
//! walk and the end-marker check only.

/// Why a JPEG is incomplete, for an error message (the caller names the file).
pub type Why = String;

#[derive(Clone, Copy, Default)]
struct Component {
    id: u8,
    h: usize,
    v: usize,
    /// Its quantisation table's slot.
    tq: usize,
}

/// A Huffman table in canonical form (JPEG Annex C), with a lookup table for codes of up to `FAST` bits.
#[derive(Clone)]
struct Huffman {
    /// `(symbol, length)` for each `FAST`-bit prefix; length 0: longer code.
    fast: Vec<(u8, u8)>,
    maxcode: [i32; 18],
    valptr: [i32; 17],
    mincode: [i32; 17],
    values: Vec<u8>,
}

const FAST: u32 = 11;

impl Huffman {
    fn new(counts: &[u8; 16], values: Vec<u8>) -> Result<Self, Why> {
        let total: usize = counts.iter().map(|&c| c as usize).sum();
        if total != values.len() || total > 256 {
            return Err("bad Huffman table".into());
        }
        let mut fast = vec![(0u8, 0u8); 1 << FAST];
        let (mut maxcode, mut valptr, mut mincode) = ([-1i32; 18], [0i32; 17], [0i32; 17]);
        let (mut code, mut k) = (0i32, 0usize);
        for len in 1..=16usize {
            let n = counts[len - 1] as usize;
            valptr[len] = k as i32;
            mincode[len] = code;
            for _ in 0..n {
                if len as u32 <= FAST {
                    let shift = FAST - len as u32;
                    let first = (code as usize) << shift;
                    for e in fast.iter_mut().skip(first).take(1 << shift) {
                        *e = (values[k], len as u8);
                    }
                }
                code += 1;
                k += 1;
            }
            maxcode[len] = if n > 0 { code - 1 } else { -1 };
            if code > (1 << len) {
                return Err("bad Huffman table (over-subscribed)".into());
            }
            code <<= 1;
        }
        maxcode[17] = i32::MAX;
        Ok(Huffman {
            fast,
            maxcode,
            valptr,
            mincode,
            values,
        })
    }
}

/// Bits of one entropy-coded segment: byte stuffing removed; stops at a marker or the end of the data and pads
/// with zero bits from there, counting how many real bits there were.
struct Bits<'a> {
    data: &'a [u8],
    pos: usize,
    acc: u64,
    n: u32,
    /// Bits pushed into `acc` since the start: all, and those from the file (not padding).
    pushed: u64,
    real_pushed: u64,
    /// The marker (second byte) the segment stopped at, if any; `pos` is at its `0xFF`.
    marker: Option<u8>,
    ended: bool,
}

impl<'a> Bits<'a> {
    fn new(data: &'a [u8], pos: usize) -> Self {
        Bits {
            data,
            pos,
            acc: 0,
            n: 0,
            pushed: 0,
            real_pushed: 0,
            marker: None,
            ended: false,
        }
    }

    /// Push bytes until more than 56 bits are held: eight bytes at once where none of them is `0xFF`.
    #[inline]
    fn fill(&mut self) {
        if self.n <= 56 && !self.ended {
            if let Some(b) = self.data.get(self.pos..self.pos + 8) {
                let w = u64::from_be_bytes(b.try_into().expect("8 bytes"));
                // A zero byte of `!w` is an `0xFF` byte of `w` (exact: no false positives or negatives).
                let x = !w;
                if x.wrapping_sub(0x0101_0101_0101_0101) & !x & 0x8080_8080_8080_8080 == 0 {
                    let k = (56 - self.n) / 8 + 1;
                    self.acc |= (w >> (64 - 8 * k)) << (64 - self.n - 8 * k);
                    self.pos += k as usize;
                    self.n += 8 * k;
                    self.pushed += 8 * k as u64;
                    self.real_pushed += 8 * k as u64;
                    return;
                }
            }
        }
        self.fill_bytes();
    }

    /// [`Bits::fill`] byte by byte: stuffed bytes, fill bytes, markers and the end.
    fn fill_bytes(&mut self) {
        while self.n <= 56 {
            let mut byte = 0u8;
            let mut real = false;
            if !self.ended {
                match self.data.get(self.pos) {
                    None => self.ended = true,
                    Some(&0xFF) => match self.data.get(self.pos + 1) {
                        Some(0) => {
                            byte = 0xFF;
                            real = true;
                            self.pos += 2;
                        }
                        Some(&0xFF) => {
                            // Fill byte before a marker.
                            self.pos += 1;
                            continue;
                        }
                        Some(&m) => {
                            self.marker = Some(m);
                            self.ended = true;
                        }
                        None => self.ended = true,
                    },
                    Some(&b) => {
                        byte = b;
                        real = true;
                        self.pos += 1;
                    }
                }
            }
            self.acc |= (byte as u64) << (56 - self.n);
            self.n += 8;
            self.pushed += 8;
            if real {
                self.real_pushed += 8;
            }
        }
    }

    #[inline]
    fn skip(&mut self, k: u32) {
        if self.n < k {
            self.fill();
        }
        self.acc <<= k;
        self.n -= k;
    }

    /// The fast table's entry for the next bits, `(symbol, code length)`; length 0 when the code is longer than
    /// [`FAST`] bits (then [`Bits::decode_long`]).
    #[inline(always)]
    fn peek_fast(&mut self, t: &Huffman) -> (u8, u8) {
        // At least 32 bits held: a fast code and its up to 15 extra bits need no fill in between.
        if self.n < 32 {
            self.fill();
        }
        t.fast[(self.acc >> (64 - FAST)) as usize]
    }

    #[inline]
    fn decode(&mut self, t: &Huffman) -> Result<u8, Why> {
        let (sym, len) = self.peek_fast(t);
        if len > 0 {
            self.skip(len as u32);
            return Ok(sym);
        }
        self.decode_long(t)
    }

    /// A code longer than [`FAST`] bits, by the canonical code's limits (at least 16 bits in the reader).
    fn decode_long(&mut self, t: &Huffman) -> Result<u8, Why> {
        for len in (FAST as usize + 1)..=16 {
            let code = (self.acc >> (64 - len)) as i32;
            if code <= t.maxcode[len] {
                let i = t.valptr[len] + code - t.mincode[len];
                let sym = *t
                    .values
                    .get(i as usize)
                    .ok_or("corrupt compressed data (bad Huffman code)")?;
                self.skip(len as u32);
                return Ok(sym);
            }
        }
        Err("corrupt compressed data (bad Huffman code)".into())
    }

    /// An AC symbol `rs` and its `rs & 15` extra bits, skipped together: one shift of the reader instead of two
    /// (the check's inner loop).
    #[inline]
    fn decode_ac(&mut self, t: &Huffman) -> Result<u8, Why> {
        let (sym, len) = self.peek_fast(t);
        if len > 0 {
            let k = len as u32 + (sym & 15) as u32;
            self.acc <<= k;
            self.n -= k;
            return Ok(sym);
        }
        let sym = self.decode_long(t)?;
        self.skip((sym & 15) as u32);
        Ok(sym)
    }

    /// Whether the bits taken so far were all in the file (not padding past a marker or the end).
    fn within_data(&self) -> bool {
        self.pushed - self.n as u64 <= self.real_pushed
    }
}

fn be16(d: &[u8], at: usize) -> Result<usize, Why> {
    match d.get(at..at + 2) {
        Some(b) => Ok(u16::from_be_bytes([b[0], b[1]]) as usize),
        None => Err("the file ends inside a header segment".into()),
    }
}

/// The DC coefficients of a single-scan baseline JPEG, kept while [`walk`] checks it ([`block_means`]).
#[derive(Default)]
struct Capture {
    /// The DC quantiser of each quantisation table slot.
    quant: [Option<u16>; 4],
    /// Each frame component's DC coefficients (quantised) on its grid of blocks, the MCUs' padding blocks included.
    planes: Vec<Vec<i32>>,
    /// Blocks across each plane.
    strides: Vec<usize>,
    /// For each component of the scan: (frame component, blocks per MCU across and down).
    layout: Vec<(usize, usize, usize)>,
    /// MCUs across the frame (blocks across, for a single-component scan).
    mcus_across: usize,
    /// The running DC predictor of each component of the scan (reset at each restart marker).
    predictors: Vec<i32>,
    /// The frame's size and components.
    frame: Option<(usize, usize, Vec<Component>)>,
    /// A scan was seen.
    scanned: bool,
    /// Something these coefficients cannot be turned into block means for (progressive or 12-bit coding, several
    /// scans, RGB or CMYK components).
    unusable: bool,
}

impl Capture {
    /// The DC quantisers of a define-quantisation-table segment.
    fn quantisers(&mut self, seg: &[u8]) {
        let mut p = 0;
        while let Some(&b) = seg.get(p) {
            let (pq, tq) = ((b >> 4) as usize, (b & 15) as usize);
            let dc = match pq {
                0 => seg.get(p + 1).map(|&v| v as u16),
                _ => seg
                    .get(p + 1..p + 3)
                    .map(|v| u16::from_be_bytes([v[0], v[1]])),
            };
            match (dc, tq < 4) {
                (Some(q), true) => self.quant[tq] = Some(q),
                _ => {
                    self.unusable = true;
                    return;
                }
            }
            p += 1 + 64 * (pq + 1);
        }
    }

    /// Set up for the scan whose components are `parts`; `false` (and unusable) for a frame larger than the decoder
    /// takes ([`crate::io::MAX_PIXELS`]), whose planes are not allocated.
    fn start_scan(
        &mut self,
        parts: &[ScanPart],
        width: usize,
        height: usize,
        comps: &[Component],
    ) -> bool {
        if (width as u64).saturating_mul(height as u64) > crate::io::MAX_PIXELS {
            self.unusable = true;
            return false;
        }
        let hmax = comps.iter().map(|c| c.h).max().unwrap_or(1);
        let vmax = comps.iter().map(|c| c.v).max().unwrap_or(1);
        self.planes = vec![Vec::new(); comps.len()];
        self.strides = vec![0; comps.len()];
        self.layout.clear();
        if let [(_, _, _, ci)] = parts {
            // One component: its own blocks in raster order.
            let across = width.div_ceil(8);
            self.mcus_across = across;
            self.strides[*ci] = across;
            self.planes[*ci] = vec![0; across * height.div_ceil(8)];
            self.layout.push((*ci, 1, 1));
        } else {
            let (mx, my) = (width.div_ceil(8 * hmax), height.div_ceil(8 * vmax));
            self.mcus_across = mx;
            for &(_, _, _, ci) in parts {
                let c = comps[ci];
                self.strides[ci] = mx * c.h;
                self.planes[ci] = vec![0; mx * c.h * my * c.v];
                self.layout.push((ci, c.h, c.v));
            }
        }
        self.predictors = vec![0; parts.len()];
        true
    }

    /// Block `b` of the scan's component `p` in MCU `m`: its DC difference `diff`.
    #[inline]
    fn put(&mut self, m: usize, p: usize, b: usize, diff: i32) {
        let (ci, h, v) = self.layout[p];
        let pred = self.predictors[p].wrapping_add(diff);
        self.predictors[p] = pred;
        let (mx, my) = (m % self.mcus_across, m / self.mcus_across);
        let (bx, by) = (mx * h + b % h, my * v + b / h);
        if let Some(slot) = self.planes[ci].get_mut(by * self.strides[ci] + bx) {
            *slot = pred;
        }
    }
}

/// The mean levels of a JPEG's 8×8 blocks, from their DC coefficients: what the survey of `--window auto` measures
/// a photo by, without decoding it.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockMeans {
    /// The photo's width in pixels.
    pub width: usize,
    /// The photo's height in pixels.
    pub height: usize,
    /// 1 (grey) or 3 (RGB).
    pub channels: usize,
    /// Blocks across and down: `width.div_ceil(8)`, `height.div_ceil(8)`.
    pub blocks: (usize, usize),
    /// Each block's mean level per channel, as a share of 255, interleaved, row by row of blocks (the blocks at
    /// the right and bottom border include the encoder's padding).
    pub means: Vec<f32>,
}

/// [`check`] and, for a complete single-scan baseline JPEG of 8-bit grey or YCbCr samples, its [`BlockMeans`]:
/// `Ok(None)` for any other JPEG (progressive, 12-bit, several scans, RGB or CMYK, luma not the largest
/// sampling), which has to be decoded.
///
/// A block's mean sample is its DC coefficient × its quantiser ÷ 8 + 128 (JPEG A.3.3); YCbCr goes to RGB by JFIF's
/// equations at each luma block, with the chroma block that covers it (a 16×16 mean with 4:2:0 chroma). Equal to
/// the mean of the decoded block's samples but for the decoder's rounding and clamping, and its smoothing of
/// subsampled chroma.
pub fn block_means(data: &[u8]) -> Result<Option<BlockMeans>, Why> {
    let mut cap = Capture::default();
    let (sequential, scans) = walk(data, Some(&mut cap))?;
    if cap.unusable || !sequential || scans != 1 {
        return Ok(None);
    }
    let Some((width, height, comps)) = cap.frame.take() else {
        return Ok(None);
    };
    let hmax = comps.iter().map(|c| c.h).max().unwrap_or(1);
    let vmax = comps.iter().map(|c| c.v).max().unwrap_or(1);
    if comps[0].h != hmax || comps[0].v != vmax {
        return Ok(None);
    }
    let mut quant = Vec::with_capacity(comps.len());
    for c in &comps {
        match cap.quant.get(c.tq).copied().flatten() {
            Some(q) => quant.push(q as f32),
            None => return Ok(None),
        }
    }
    let blocks = (width.div_ceil(8), height.div_ceil(8));
    let channels = comps.len();
    // Every component's plane covers the luma blocks it is read at (a scan that named one component twice leaves
    // another without one).
    for (ci, c) in comps.iter().enumerate() {
        let (x, y) = ((blocks.0 - 1) * c.h / hmax, (blocks.1 - 1) * c.v / vmax);
        if cap
            .planes
            .get(ci)
            .is_none_or(|p| p.len() <= y * cap.strides[ci] + x)
        {
            return Ok(None);
        }
    }
    let mut means = Vec::with_capacity(blocks.0 * blocks.1 * channels);
    // Component `ci`'s mean level at luma block (bx, by).
    let level = |ci: usize, bx: usize, by: usize| {
        let c = comps[ci];
        let (x, y) = (bx * c.h / hmax, by * c.v / vmax);
        let dc = cap.planes[ci][y * cap.strides[ci] + x];
        dc as f32 * quant[ci] / 8.0 + 128.0
    };
    for by in 0..blocks.1 {
        for bx in 0..blocks.0 {
            let y = level(0, bx, by);
            if channels == 1 {
                means.push(y.clamp(0.0, 255.0) / 255.0);
                continue;
            }
            let (cb, cr) = (level(1, bx, by) - 128.0, level(2, bx, by) - 128.0);
            for v in [
                y + 1.402 * cr,
                y - 0.344_136 * cb - 0.714_136 * cr,
                y + 1.772 * cb,
            ] {
                means.push(v.clamp(0.0, 255.0) / 255.0);
            }
        }
    }
    Ok(Some(BlockMeans {
        width,
        height,
        channels,
        blocks,
        means,
    }))
}

/// Position of the next marker (its `0xFF`) at or after `pos` that ends an entropy-coded segment (not a stuffed
/// byte, not a restart marker), if any.
fn next_marker(d: &[u8], mut pos: usize) -> Option<usize> {
    while pos + 1 < d.len() {
        if d[pos] == 0xFF {
            let m = d[pos + 1];
            if m != 0 && m != 0xFF && !(0xD0..=0xD7).contains(&m) {
                return Some(pos);
            }
            pos += if m == 0xFF { 1 } else { 2 };
        } else {
            pos += 1;
        }
    }
    None
}

/// Width, height and components of a start-of-frame segment.
fn frame_header(seg: &[u8]) -> Result<(usize, usize, Vec<Component>), Why> {
    if seg.len() < 6 {
        return Err("bad frame header".into());
    }
    let height = u16::from_be_bytes([seg[1], seg[2]]) as usize;
    let width = u16::from_be_bytes([seg[3], seg[4]]) as usize;
    let nc = seg[5] as usize;
    if seg.len() < 6 + 3 * nc || nc == 0 || width == 0 || height == 0 {
        return Err("bad frame header".into());
    }
    let comps: Vec<Component> = (0..nc)
        .map(|i| Component {
            id: seg[6 + 3 * i],
            h: (seg[7 + 3 * i] >> 4) as usize,
            v: (seg[7 + 3 * i] & 15) as usize,
            tq: (seg[8 + 3 * i] & 15) as usize,
        })
        .collect();
    if comps
        .iter()
        .any(|c| !(1..=4).contains(&c.h) || !(1..=4).contains(&c.v))
    {
        return Err("bad sampling factors in the frame header".into());
    }
    Ok((width, height, comps))
}

/// Store the Huffman tables of a define-Huffman-table segment in `dc` and `ac` by their slot.
fn huffman_tables(
    seg: &[u8],
    dc: &mut [Option<Huffman>; 4],
    ac: &mut [Option<Huffman>; 4],
) -> Result<(), Why> {
    let mut p = 0;
    while p < seg.len() {
        let tc = seg[p] >> 4;
        let th = (seg[p] & 15) as usize;
        let counts: [u8; 16] = seg
            .get(p + 1..p + 17)
            .and_then(|c| c.try_into().ok())
            .ok_or("bad Huffman table segment")?;
        let total: usize = counts.iter().map(|&c| c as usize).sum();
        let values = seg
            .get(p + 17..p + 17 + total)
            .ok_or("bad Huffman table segment")?
            .to_vec();
        if th > 3 || tc > 1 {
            return Err("bad Huffman table segment".into());
        }
        let t = Huffman::new(&counts, values)?;
        if tc == 0 {
            dc[th] = Some(t);
        } else {
            ac[th] = Some(t);
        }
        p += 17 + total;
    }
    Ok(())
}

/// `Ok` when the JPEG in `data` holds all its compressed data and ends with an end-of-image marker; `Err` says
/// what is missing. See the module documentation.
pub fn check(data: &[u8]) -> Result<(), Why> {
    walk(data, None).map(|_| ())
}

/// [`check`] for every JPEG, and whether it is a sequential one of more than one scan (a non-interleaved JPEG,
/// one scan per component). A progressive JPEG's scans are Huffman-decoded by libjpeg-turbo's decoder (ported to
/// Rust) in its strict mode, which refuses a scan whose data ends before its last block: the marker walk alone
/// accepts a progressive JPEG cut inside a scan and closed with an end marker.
pub fn check_all(data: &[u8]) -> Result<bool, Why> {
    let (sequential, scans) = walk(data, None)?;
    if !sequential {
        libjpeg_turbo_rs::read_coefficients(data).map_err(|e| {
            format!("a scan of this progressive JPEG is incomplete or damaged ({e})")
        })?;
    }
    Ok(sequential && scans > 1)
}

/// The walk of [`check`]: whether the frame is sequential, and how many scans it has. With a `capture`, the DC
/// coefficients of a single-scan baseline JPEG are kept as it goes ([`block_means`]).
fn walk(data: &[u8], mut capture: Option<&mut Capture>) -> Result<(bool, usize), Why> {
    if data.get(..2) != Some(&[0xFF, 0xD8]) {
        return Err("not a JPEG (no start-of-image marker)".into());
    }
    let mut pos = 2;
    let mut frame: Option<(usize, usize, Vec<Component>)> = None;
    let mut baseline = false;
    let mut dc: [Option<Huffman>; 4] = [None, None, None, None];
    let mut ac: [Option<Huffman>; 4] = [None, None, None, None];
    let mut restart = 0usize;
    let mut scans = 0usize;
    loop {
        // Markers may be preceded by fill bytes 0xFF.
        while data.get(pos) == Some(&0xFF) && data.get(pos + 1) == Some(&0xFF) {
            pos += 1;
        }
        let (Some(&0xFF), Some(&m)) = (data.get(pos), data.get(pos + 1)) else {
            return Err(no_marker(data, pos));
        };
        pos += 2;
        match m {
            0xD9 => {
                return if scans == 0 {
                    Err("end-of-image marker before any image data".into())
                } else {
                    Ok((baseline, scans))
                };
            }
            0x01 | 0xD0..=0xD7 => continue,
            _ => {}
        }
        let len = be16(data, pos)?;
        if len < 2 || pos + len > data.len() {
            return Err("the file ends inside a header segment (truncated)".into());
        }
        let seg = &data[pos + 2..pos + len];
        match m {
            0xC0..=0xCF if m != 0xC4 && m != 0xC8 && m != 0xCC => {
                baseline = m == 0xC0 || m == 0xC1;
                frame = Some(frame_header(seg)?);
                if let Some(cap) = capture.as_deref_mut() {
                    // 8-bit samples only: the block means are taken as 8-bit levels.
                    cap.unusable |= !baseline || seg.first() != Some(&8);
                    cap.frame = frame.clone();
                }
            }
            0xDB => {
                if let Some(cap) = capture.as_deref_mut() {
                    cap.quantisers(seg);
                }
            }
            0xEE => {
                if let Some(cap) = capture.as_deref_mut() {
                    // Adobe's colour transform flag: 0 is RGB (or CMYK) as stored, not YCbCr.
                    cap.unusable |= seg.starts_with(b"Adobe") && seg.get(11) == Some(&0);
                }
            }
            0xC4 => huffman_tables(seg, &mut dc, &mut ac)?,
            0xDD => restart = be16(data, pos + 2)?,
            0xDA => {
                scans += 1;
                let start = pos + len;
                let end = if baseline {
                    let (w, h, comps) = frame.as_ref().ok_or("scan before the frame header")?;
                    if let Some(c) = capture.as_deref_mut() {
                        // One scan holding every component, grey or YCbCr (not RGB by its component names).
                        let n = comps.len();
                        c.unusable |= c.scanned
                            || seg.first() != Some(&(n as u8))
                            || !(n == 1 || n == 3)
                            || (n == 3 && comps.iter().map(|c| c.id).eq(*b"RGB"));
                        c.scanned = true;
                    }
                    let cap = capture.as_deref_mut().filter(|c| !c.unusable);
                    scan_baseline(data, start, seg, *w, *h, comps, &dc, &ac, restart, cap)?
                } else {
                    start
                };
                pos = next_marker(data, end).ok_or_else(|| unended_scan(data, end))?;
                continue;
            }
            _ => {}
        }
        pos += len;
    }
}

/// Why there is no marker at `pos`, where [`walk`] expects one.
fn no_marker(data: &[u8], pos: usize) -> Why {
    if pos >= data.len() {
        "the file ends before its end-of-image marker (truncated)".into()
    } else if data[pos..].iter().all(|&b| b == 0) {
        format!(
            "{} zero bytes where the next marker should be (a zero-filled tail: the file was not completely \
             written)",
            data.len() - pos
        )
    } else {
        format!("no marker at byte {pos} (damaged)")
    }
}

/// Why the compressed data from `end` on has no marker after it.
fn unended_scan(data: &[u8], end: usize) -> Why {
    if data[end..].iter().rev().take(64).all(|&b| b == 0) {
        "the compressed data runs into a zero-filled tail without an end marker (the file was not completely \
         written)"
            .to_string()
    } else {
        "the file ends inside the compressed data (truncated)".to_string()
    }
}

/// Width and height from a JPEG's frame header, reading the marker segments before it and nothing else (the
/// `image` crate's JPEG reader reads the whole file first, tail included).
pub fn dimensions(mut r: impl std::io::Read + std::io::Seek) -> Result<(usize, usize), Why> {
    let io = |e: std::io::Error| format!("cannot read the header: {e}");
    let mut b = [0u8; 2];
    r.read_exact(&mut b).map_err(io)?;
    if b != [0xFF, 0xD8] {
        return Err("not a JPEG (no start-of-image marker)".into());
    }
    loop {
        r.read_exact(&mut b).map_err(io)?;
        while b[0] == 0xFF && b[1] == 0xFF {
            r.read_exact(&mut b[1..]).map_err(io)?;
        }
        if b[0] != 0xFF {
            return Err("no marker where the next header segment should be (damaged)".into());
        }
        let m = b[1];
        if m == 0x01 || (0xD0..=0xD7).contains(&m) {
            continue;
        }
        if m == 0xD9 || m == 0xDA {
            return Err("no frame header before the image data".into());
        }
        r.read_exact(&mut b).map_err(io)?;
        let len = u16::from_be_bytes(b) as i64;
        if len < 2 {
            return Err("bad header segment length".into());
        }
        if matches!(m, 0xC0..=0xCF) && !matches!(m, 0xC4 | 0xC8 | 0xCC) {
            let mut f = [0u8; 5];
            r.read_exact(&mut f).map_err(io)?;
            let height = u16::from_be_bytes([f[1], f[2]]) as usize;
            let width = u16::from_be_bytes([f[3], f[4]]) as usize;
            return Ok((width, height));
        }
        r.seek(std::io::SeekFrom::Current(len - 2)).map_err(io)?;
    }
}

/// One scan component: (blocks per MCU, DC table, AC table, the component's index in the frame).
type ScanPart<'t> = (usize, &'t Huffman, &'t Huffman, usize);

/// The components of a scan from its header `seg`, and the number of MCUs (or blocks, for one component) it holds.
fn scan_parts<'t>(
    seg: &[u8],
    width: usize,
    height: usize,
    comps: &[Component],
    dc: &'t [Option<Huffman>; 4],
    ac: &'t [Option<Huffman>; 4],
) -> Result<(Vec<ScanPart<'t>>, usize), Why> {
    let ns = *seg.first().ok_or("bad scan header")? as usize;
    if ns == 0 || seg.len() < 1 + 2 * ns + 3 {
        return Err("bad scan header".into());
    }
    let hmax = comps.iter().map(|c| c.h).max().unwrap_or(1);
    let vmax = comps.iter().map(|c| c.v).max().unwrap_or(1);
    // For each component of the scan: (blocks per MCU across, down, DC table, AC table).
    let mut parts = Vec::with_capacity(ns);
    let mut single = None;
    for i in 0..ns {
        let id = seg[1 + 2 * i];
        let t = seg[2 + 2 * i];
        let ci = comps
            .iter()
            .position(|c| c.id == id)
            .ok_or("scan names a component the frame does not have")?;
        let c = &comps[ci];
        let (td, ta) = ((t >> 4) as usize, (t & 15) as usize);
        let d = dc
            .get(td)
            .and_then(|t| t.as_ref())
            .ok_or("missing DC Huffman table")?;
        let a = ac
            .get(ta)
            .and_then(|t| t.as_ref())
            .ok_or("missing AC Huffman table")?;
        if ns == 1 {
            let cw = (width * c.h).div_ceil(hmax);
            let ch = (height * c.v).div_ceil(vmax);
            single = Some(cw.div_ceil(8) * ch.div_ceil(8));
            parts.push((1usize, d, a, ci));
        } else {
            parts.push((c.h * c.v, d, a, ci));
        }
    }
    let mcus = match single {
        Some(n) => n,
        None => width.div_ceil(8 * hmax) * height.div_ceil(8 * vmax),
    };
    Ok((parts, mcus))
}

/// Huffman-decode one block's DC and AC coefficients, checking only that they are well formed; returns the DC
/// coefficient's difference to the previous block's of its component (JPEG F.2.2.1).
fn skip_block(bits: &mut Bits, d: &Huffman, a: &Huffman) -> Result<i32, Why> {
    let s = bits.decode(d)? as u32;
    if s > 16 {
        return Err("corrupt compressed data (bad DC size)".into());
    }
    let diff = if s == 0 {
        0
    } else {
        if bits.n < s {
            bits.fill();
        }
        let v = (bits.acc >> (64 - s)) as i32;
        if v < 1 << (s - 1) {
            v - (1 << s) + 1
        } else {
            v
        }
    };
    bits.skip(s);
    let mut k = 1;
    while k < 64 {
        let rs = bits.decode_ac(a)?;
        let (r, s) = ((rs >> 4) as usize, rs & 15);
        if s == 0 {
            if r == 15 {
                k += 16;
                continue;
            }
            break;
        }
        k += r + 1;
    }
    if k > 64 {
        return Err("corrupt compressed data (more than 64 coefficients in a block)".into());
    }
    Ok(diff)
}

/// Huffman-decode one baseline scan starting at `start`; returns the position where its data ends.
#[allow(clippy::too_many_arguments)]
fn scan_baseline(
    data: &[u8],
    start: usize,
    seg: &[u8],
    width: usize,
    height: usize,
    comps: &[Component],
    dc: &[Option<Huffman>; 4],
    ac: &[Option<Huffman>; 4],
    restart: usize,
    capture: Option<&mut Capture>,
) -> Result<usize, Why> {
    let (parts, mcus) = scan_parts(seg, width, height, comps, dc, ac)?;
    let mut capture =
        capture.and_then(|cap| cap.start_scan(&parts, width, height, comps).then_some(cap));
    let mut bits = Bits::new(data, start);
    let short = |done: usize| {
        format!(
            "the compressed data ends after {done} of {mcus} blocks/MCUs ({:.0} % of the image): the file was \
             cut short",
            100.0 * done as f64 / mcus as f64
        )
    };
    for m in 0..mcus {
        if restart > 0 && m > 0 && m % restart == 0 {
            // Byte-aligned restart marker expected here.
            if !bits.within_data() {
                return Err(short(m));
            }
            // The reader stops at a marker; at most a padding byte (possibly stuffed) lies before it.
            let p = next_marker_any(data, bits.pos);
            match data.get(p + 1) {
                Some(&r) if (0xD0..=0xD7).contains(&r) && p - bits.pos <= 3 => {
                    bits = Bits::new(data, p + 2);
                    if let Some(cap) = capture.as_deref_mut() {
                        cap.predictors.fill(0);
                    }
                }
                _ => return Err(short(m)),
            }
        }
        match capture.as_deref_mut() {
            None => {
                for &(blocks, d, a, _) in &parts {
                    for _ in 0..blocks {
                        skip_block(&mut bits, d, a)?;
                    }
                }
            }
            Some(cap) => {
                for (p, &(blocks, d, a, _)) in parts.iter().enumerate() {
                    for b in 0..blocks {
                        let diff = skip_block(&mut bits, d, a)?;
                        cap.put(m, p, b, diff);
                    }
                }
            }
        }
        if bits.ended && !bits.within_data() {
            return Err(short(m));
        }
    }
    if !bits.within_data() {
        return Err(short(mcus));
    }
    // The reader never passes a marker: the rest of this scan's data (if any) starts at its position.
    Ok(bits.pos)
}

/// The next `0xFF xx` marker of any kind (restart markers included) at or after `pos`.
fn next_marker_any(d: &[u8], mut pos: usize) -> usize {
    while pos + 1 < d.len() {
        if d[pos] == 0xFF && d[pos + 1] != 0 && d[pos + 1] != 0xFF {
            return pos;
        }
        pos += 1;
    }
    d.len()
}

/// Verdicts of [`check_all`] on JPEGs found complete, kept while a run reads its photos more than once (the survey
/// of `--window auto`, then the correction): a later read of the same bytes takes the verdict instead of walking
/// the entropy data again. Keyed by the bytes' length and two hashes of them with random keys of this process
/// (SipHash; 128 bits in all): a file that changed in between is a new key, checked again.
struct Remembered {
    hashers: [std::hash::RandomState; 2],
    verdicts: std::collections::HashMap<(usize, u64, u64), bool>,
    /// Runs that asked for it: the verdicts go when the last one ends.
    users: usize,
}

/// At most this many verdicts kept (about 10 MB); past them photos are checked on every read.
const MAX_REMEMBERED: usize = 1 << 18;

static REMEMBERED: std::sync::Mutex<Option<Remembered>> = std::sync::Mutex::new(None);

fn remembered() -> std::sync::MutexGuard<'static, Option<Remembered>> {
    REMEMBERED.lock().unwrap_or_else(|e| e.into_inner())
}

/// While held, [`check_all_remembered`] keeps the verdicts of the JPEGs it finds complete.
pub(crate) struct RememberChecks(());

impl RememberChecks {
    pub(crate) fn start() -> Self {
        let mut r = remembered();
        let r = r.get_or_insert_with(|| Remembered {
            hashers: Default::default(),
            verdicts: Default::default(),
            users: 0,
        });
        r.users += 1;
        RememberChecks(())
    }
}

impl Drop for RememberChecks {
    fn drop(&mut self) {
        let mut r = remembered();
        if let Some(m) = r.as_mut() {
            m.users -= 1;
            if m.users == 0 {
                *r = None;
            }
        }
    }
}

/// The key a verdict on `data` is kept under, while a [`RememberChecks`] is held.
fn remembered_key(data: &[u8]) -> Option<(usize, u64, u64)> {
    use std::hash::BuildHasher;
    let hashers = remembered().as_ref().map(|r| r.hashers.clone())?;
    Some((
        data.len(),
        hashers[0].hash_one(data),
        hashers[1].hash_one(data),
    ))
}

/// Keep the verdict `v` of [`check_all`] under `key`.
fn remember(key: (usize, u64, u64), v: bool) {
    if let Some(r) = remembered().as_mut() {
        if r.verdicts.len() < MAX_REMEMBERED {
            r.verdicts.insert(key, v);
        }
    }
}

/// [`check_all`], or its verdict on the same bytes earlier while a [`RememberChecks`] is held.
pub(crate) fn check_all_remembered(data: &[u8]) -> Result<bool, Why> {
    let Some(key) = remembered_key(data) else {
        return check_all(data);
    };
    if let Some(&v) = remembered().as_ref().and_then(|r| r.verdicts.get(&key)) {
        return Ok(v);
    }
    let v = check_all(data)?;
    remember(key, v);
    Ok(v)
}

/// [`block_means`], keeping the check's verdict on the JPEGs it reads whole (a single-scan sequential JPEG:
/// [`check_all`] gives `Ok(false)`), so that the decode of the same bytes later in the run takes it.
pub(crate) fn block_means_remembered(data: &[u8]) -> Result<Option<BlockMeans>, Why> {
    let means = block_means(data)?;
    if means.is_some() {
        if let Some(key) = remembered_key(data) {
            remember(key, false);
        }
    }
    Ok(means)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bits of an entropy-coded segment written out independently: stuffed `FF 00` is one `FF`, fill bytes
    /// `FF FF` before a marker are dropped, the segment stops at a marker or the end.
    fn reference_bits(d: &[u8]) -> Vec<bool> {
        let mut bytes = Vec::new();
        let mut i = 0;
        while i < d.len() {
            if d[i] == 0xFF {
                match d.get(i + 1) {
                    Some(0) => {
                        bytes.push(0xFF);
                        i += 2;
                    }
                    Some(0xFF) => i += 1,
                    _ => break,
                }
            } else {
                bytes.push(d[i]);
                i += 1;
            }
        }
        bytes
            .iter()
            .flat_map(|b| (0..8).rev().map(move |k| (b >> k) & 1 == 1))
            .collect()
    }

    /// The reader gives the same bits as the reference, in reads of 1 to 16 bits, and counts the real ones; past the end it pads with zeros.
    #[test]
    fn bits_match_a_byte_by_byte_reference() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for case in 0..200 {
            let len = 1 + (next() % 300) as usize;
            let mut d: Vec<u8> = Vec::with_capacity(len + 4);
            while d.len() < len {
                let r = next();
                match r % 40 {
                    0 => d.extend_from_slice(&[0xFF, 0x00]),
                    1 => d.extend_from_slice(&[0xFF, 0xFF, 0x00]),
                    _ => d.push((r >> 8) as u8 & 0xFE),
                }
            }
            if case % 2 == 0 {
                d.extend_from_slice(&[0xFF, 0xD9]);
            }
            let want = reference_bits(&d);
            let mut bits = Bits::new(&d, 0);
            let mut at = 0usize;
            while at < want.len() + 40 {
                let k = 1 + (next() % 16) as u32;
                if bits.n < k {
                    bits.fill();
                }
                let got = bits.acc >> (64 - k);
                for j in 0..k as usize {
                    let expect = want.get(at + j).copied().unwrap_or(false);
                    let bit = (got >> (k as usize - 1 - j)) & 1 == 1;
                    assert_eq!(bit, expect, "case {case}, bit {}", at + j);
                }
                bits.skip(k);
                at += k as usize;
                assert_eq!(bits.within_data(), at <= want.len(), "case {case}, at {at}");
            }
            if case % 2 == 0 {
                assert_eq!(bits.marker, Some(0xD9), "case {case}");
            }
        }
    }

    /// A test photo: a texture of up to 50 levels (the same in every channel) on colour gradients of a fraction
    /// of a level per pixel, within 30..225 (no clamping in the decoder); `channels` 1 or 3.
    fn texture(w: usize, h: usize, channels: usize, seed: u64) -> Vec<u8> {
        let mut state = seed | 1;
        let mut px = Vec::with_capacity(w * h * channels);
        for y in 0..h {
            for x in 0..w {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let texture = (state % 41) as f64 - 20.0 + 10.0 * ((x / 5 + y / 7) % 3) as f64;
                let (xf, yf) = (x as f64, y as f64);
                for ramp in [60.0 + 0.3 * xf, 70.0 + 0.25 * yf, 90.0 + 0.2 * (xf + yf)]
                    .into_iter()
                    .take(channels)
                {
                    px.push((ramp + texture).clamp(30.0, 225.0) as u8);
                }
            }
        }
        px
    }

    /// Mean of the decoded samples of each complete 8×8 block, against [`block_means`]: (largest, mean) absolute
    /// difference in levels over the blocks and channels.
    fn against_decoded(jpeg: &[u8], w: usize, h: usize, channels: usize) -> (f32, f32) {
        // zune-jpeg, the decoder the correction reads the same photos with.
        let photo =
            super::super::decode_jpeg_zune(jpeg, |n| vec![0; n]).expect("the decoder reads it");
        let l = photo.layout;
        assert_eq!((l.width, l.height, l.channels), (w, h, channels));
        let crate::method::raster::Samples::U8(px) = photo.samples else {
            panic!("8-bit samples")
        };
        let b = block_means(jpeg)
            .unwrap()
            .expect("a baseline single-scan JPEG");
        assert_eq!((b.width, b.height, b.channels), (w, h, channels));
        assert_eq!(b.blocks, (w.div_ceil(8), h.div_ceil(8)));
        assert_eq!(b.means.len(), b.blocks.0 * b.blocks.1 * channels);
        let (mut worst, mut sum, mut n) = (0f32, 0f32, 0f32);
        for by in 0..h / 8 {
            for bx in 0..w / 8 {
                for c in 0..channels {
                    let mut total = 0u32;
                    for y in by * 8..by * 8 + 8 {
                        for x in bx * 8..bx * 8 + 8 {
                            total += px[(y * w + x) * channels + c] as u32;
                        }
                    }
                    let want = total as f32 / 64.0;
                    let got = 255.0 * b.means[(by * b.blocks.0 + bx) * channels + c];
                    worst = worst.max((got - want).abs());
                    sum += (got - want).abs();
                    n += 1.0;
                }
            }
        }
        (worst, sum / n)
    }

    /// The block means from the DC coefficients are the decoded blocks' means, within the quantisation of the DC
    /// coefficients (grey: a tenth of a level; RGB: the chroma's quantiser scaled by the colour conversion, about a
    /// level) and, with subsampled chroma, its 16-pixel means where the decoder's upsampled chroma varies within
    /// them; for odd sizes (partial MCUs), restart intervals and two encoders.
    #[test]
    fn block_means_are_the_decoded_blocks_means() {
        use libjpeg_turbo_rs::{compress, PixelFormat, Subsampling};
        for (w, h) in [(64, 48), (203, 141), (17, 9)] {
            let rgb = texture(w, h, 3, (w * h) as u64);
            for (s, tolerance) in [
                (Subsampling::S444, (1.5, 0.3)),
                (Subsampling::S422, (2.5, 1.0)),
                (Subsampling::S420, (2.5, 1.0)),
            ] {
                let jpeg = compress(&rgb, w, h, PixelFormat::Rgb, 92, s).unwrap();
                let (worst, mean) = against_decoded(&jpeg, w, h, 3);
                assert!(
                    worst <= tolerance.0 && mean <= tolerance.1,
                    "{w}x{h} {s:?}: worst {worst}, mean {mean}"
                );
            }
            let grey = texture(w, h, 1, 7);
            let jpeg =
                compress(&grey, w, h, PixelFormat::Grayscale, 85, Subsampling::S444).unwrap();
            let (worst, mean) = against_decoded(&jpeg, w, h, 1);
            assert!(
                worst <= 0.25 && mean <= 0.05,
                "{w}x{h} grey: worst {worst}, mean {mean}"
            );
            // Another encoder, with restart markers every 3 MCUs (the predictors start again at each).
            for restart in [1, 3] {
                let mut jpeg = Vec::new();
                let mut enc = jpeg_encoder::Encoder::new(&mut jpeg, 90);
                enc.set_restart_interval(restart);
                enc.encode(&rgb, w as u16, h as u16, jpeg_encoder::ColorType::Rgb)
                    .unwrap();
                let (worst, mean) = against_decoded(&jpeg, w, h, 3);
                assert!(
                    worst <= 1.5 && mean <= 0.4,
                    "{w}x{h} restart {restart}: worst {worst}, mean {mean}"
                );
            }
        }
    }

    /// The DC coefficients kept during the check are those of an independent coefficient reader (libjpeg-turbo's,
    /// ported to Rust), block by block, every component, for every sampling, odd sizes and restart intervals.
    #[test]
    fn the_dc_coefficients_are_the_reference_readers() {
        use libjpeg_turbo_rs::{compress, PixelFormat, Subsampling};
        for (w, h) in [(64, 48), (203, 141), (17, 9), (33, 40)] {
            let rgb = texture(w, h, 3, 11);
            let mut files = Vec::new();
            for s in [Subsampling::S444, Subsampling::S422, Subsampling::S420] {
                files.push(compress(&rgb, w, h, PixelFormat::Rgb, 90, s).unwrap());
            }
            for restart in [1, 2, 5] {
                let mut jpeg = Vec::new();
                let mut enc = jpeg_encoder::Encoder::new(&mut jpeg, 80);
                enc.set_sampling_factor(jpeg_encoder::SamplingFactor::R_4_2_0);
                enc.set_restart_interval(restart);
                enc.encode(&rgb, w as u16, h as u16, jpeg_encoder::ColorType::Rgb)
                    .unwrap();
                files.push(jpeg);
            }
            for (f, jpeg) in files.iter().enumerate() {
                let mut cap = Capture::default();
                walk(jpeg, Some(&mut cap)).unwrap();
                assert!(!cap.unusable, "{w}x{h} file {f}");
                let reference = libjpeg_turbo_rs::read_coefficients(jpeg).unwrap();
                assert_eq!(reference.components.len(), 3);
                for (ci, rc) in reference.components.iter().enumerate() {
                    let mut compared = 0;
                    for by in 0..rc.blocks_y {
                        for bx in 0..rc.blocks_x {
                            let Some(&got) = cap.planes[ci].get(by * cap.strides[ci] + bx) else {
                                continue;
                            };
                            if bx >= cap.strides[ci] {
                                continue;
                            }
                            let want = rc.blocks[by * rc.blocks_x + bx][0] as i32;
                            assert_eq!(
                                got, want,
                                "{w}x{h} file {f} component {ci} block ({bx}, {by})"
                            );
                            compared += 1;
                        }
                    }
                    assert!(compared > 0, "{w}x{h} file {f} component {ci}");
                }
            }
        }
    }

    /// A frame larger than the decoder takes gets no planes (a header may claim 65535×65535 pixels before data of a
    /// few bytes): the capture is given up, the check goes on.
    #[test]
    fn no_planes_for_a_frame_larger_than_the_decoder_takes() {
        let comps = [Component {
            id: 1,
            h: 1,
            v: 1,
            tq: 0,
        }];
        let table =
            Huffman::new(&[0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0], vec![0]).unwrap();
        let parts: Vec<ScanPart> = vec![(1, &table, &table, 0)];
        let mut cap = Capture::default();
        assert!(!cap.start_scan(&parts, 65535, 65535, &comps));
        assert!(cap.unusable && cap.planes.iter().all(|p| p.is_empty()));
        let mut cap = Capture::default();
        assert!(cap.start_scan(&parts, 640, 480, &comps));
        assert_eq!(cap.planes[0].len(), 80 * 60);
    }

    /// What the DC coefficients do not give is refused (`Ok(None)`: decode it) and what the check refuses stays
    /// refused: a progressive JPEG, a JPEG cut short; the verdict kept for the complete one is the check's.
    #[test]
    fn block_means_refuse_what_they_cannot_read() {
        use libjpeg_turbo_rs::{compress, PixelFormat, Subsampling};
        let rgb = texture(96, 64, 3, 5);
        let mut progressive = Vec::new();
        let mut enc = jpeg_encoder::Encoder::new(&mut progressive, 90);
        enc.set_progressive(true);
        enc.encode(&rgb, 96, 64, jpeg_encoder::ColorType::Rgb)
            .unwrap();
        assert_eq!(block_means(&progressive), Ok(None));
        let jpeg = compress(&rgb, 96, 64, PixelFormat::Rgb, 92, Subsampling::S420).unwrap();
        let cut = [&jpeg[..jpeg.len() / 2], &[0xFF, 0xD9][..]].concat();
        assert_eq!(block_means(&cut).err(), check_all(&cut).err());
        assert!(block_means(&cut).is_err());
        let keep = RememberChecks::start();
        assert!(block_means_remembered(&jpeg).unwrap().is_some());
        assert_eq!(check_all_remembered(&jpeg), check_all(&jpeg));
        drop(keep);
    }

    /// A verdict is taken again for the same bytes only: a copy cut short and closed with an end marker is
    /// checked (and refused) however often the complete file was seen.
    #[test]
    fn a_remembered_verdict_is_for_the_same_bytes_only() {
        use libjpeg_turbo_rs::{compress, PixelFormat, Subsampling};
        use std::hash::BuildHasher;
        let px: Vec<u8> = (0..96 * 64 * 3).map(|i| (i * 37 % 251) as u8).collect();
        let jpeg = compress(&px, 96, 64, PixelFormat::Rgb, 92, Subsampling::S420).unwrap();
        let cut = [&jpeg[..jpeg.len() * 2 / 3], &[0xFF, 0xD9][..]].concat();
        assert_eq!(check_all(&jpeg), Ok(false));
        assert!(check_all(&cut).is_err());
        let keep = RememberChecks::start();
        for _ in 0..3 {
            assert_eq!(check_all_remembered(&jpeg), Ok(false));
            assert!(check_all_remembered(&cut).is_err());
        }
        let held = |b: &[u8]| {
            let r = remembered();
            let r = r.as_ref().expect("held while a RememberChecks lives");
            let k = (b.len(), r.hashers[0].hash_one(b), r.hashers[1].hash_one(b));
            r.verdicts.get(&k).copied()
        };
        assert_eq!(held(&jpeg), Some(false));
        assert_eq!(held(&cut), None);
        drop(keep);
    }
}
