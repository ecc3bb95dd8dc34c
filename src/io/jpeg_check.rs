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
    walk(data).map(|_| ())
}

/// [`check`] for every JPEG, and whether it is a sequential one of more than one scan (a non-interleaved JPEG,
/// one scan per component). A progressive JPEG's scans are Huffman-decoded by libjpeg-turbo's decoder (ported to
/// Rust) in its strict mode, which refuses a scan whose data ends before its last block: the marker walk alone
/// accepts a progressive JPEG cut inside a scan and closed with an end marker.
pub fn check_all(data: &[u8]) -> Result<bool, Why> {
    let (sequential, scans) = walk(data)?;
    if !sequential {
        libjpeg_turbo_rs::read_coefficients(data).map_err(|e| {
            format!("a scan of this progressive JPEG is incomplete or damaged ({e})")
        })?;
    }
    Ok(sequential && scans > 1)
}

/// The walk of [`check`]: whether the frame is sequential, and how many scans it has.
fn walk(data: &[u8]) -> Result<(bool, usize), Why> {
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
            return Err(if pos >= data.len() {
                "the file ends before its end-of-image marker (truncated)".into()
            } else if data[pos..].iter().all(|&b| b == 0) {
                format!(
                    "{} zero bytes where the next marker should be (a zero-filled tail: the file was not \
                     completely written)",
                    data.len() - pos
                )
            } else {
                format!("no marker at byte {pos} (damaged)")
            });
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
            }
            0xC4 => huffman_tables(seg, &mut dc, &mut ac)?,
            0xDD => restart = be16(data, pos + 2)?,
            0xDA => {
                scans += 1;
                let start = pos + len;
                let end = if baseline {
                    let (w, h, comps) = frame.as_ref().ok_or("scan before the frame header")?;
                    scan_baseline(data, start, seg, *w, *h, comps, &dc, &ac, restart)?
                } else {
                    start
                };
                pos = next_marker(data, end).ok_or_else(|| {
                    if data[end..].iter().rev().take(64).all(|&b| b == 0) {
                        "the compressed data runs into a zero-filled tail without an end marker (the file was \
                         not completely written)"
                            .to_string()
                    } else {
                        "the file ends inside the compressed data (truncated)".to_string()
                    }
                })?;
                continue;
            }
            _ => {}
        }
        pos += len;
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

/// One scan component: (blocks per MCU, DC table, AC table).
type ScanPart<'t> = (usize, &'t Huffman, &'t Huffman);

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
        let c = comps
            .iter()
            .find(|c| c.id == id)
            .ok_or("scan names a component the frame does not have")?;
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
            parts.push((1usize, d, a));
        } else {
            parts.push((c.h * c.v, d, a));
        }
    }
    let mcus = match single {
        Some(n) => n,
        None => width.div_ceil(8 * hmax) * height.div_ceil(8 * vmax),
    };
    Ok((parts, mcus))
}

/// Huffman-decode one block's DC and AC coefficients, checking only that they are well formed.
fn skip_block(bits: &mut Bits, d: &Huffman, a: &Huffman) -> Result<(), Why> {
    let s = bits.decode(d)? as u32;
    if s > 16 {
        return Err("corrupt compressed data (bad DC size)".into());
    }
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
    Ok(())
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
) -> Result<usize, Why> {
    let (parts, mcus) = scan_parts(seg, width, height, comps, dc, ac)?;
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
                }
                _ => return Err(short(m)),
            }
        }
        for &(blocks, d, a) in &parts {
            for _ in 0..blocks {
                skip_block(&mut bits, d, a)?;
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

/// [`check_all`], or its verdict on the same bytes earlier while a [`RememberChecks`] is held.
pub(crate) fn check_all_remembered(data: &[u8]) -> Result<bool, Why> {
    use std::hash::BuildHasher;
    let Some(hashers) = remembered().as_ref().map(|r| r.hashers.clone()) else {
        return check_all(data);
    };
    let key = (
        data.len(),
        hashers[0].hash_one(data),
        hashers[1].hash_one(data),
    );
    if let Some(&v) = remembered().as_ref().and_then(|r| r.verdicts.get(&key)) {
        return Ok(v);
    }
    let v = check_all(data)?;
    if let Some(r) = remembered().as_mut() {
        if r.verdicts.len() < MAX_REMEMBERED {
            r.verdicts.insert(key, v);
        }
    }
    Ok(v)
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
