//! TIFF image file directories (IFDs): the structure of an EXIF block and of a TIFF file's own tags.
//!
//! An IFD is a list of entries `(tag, type, count, value)`; values longer than four bytes live elsewhere in the
//! file, at an offset. Three tags point to further IFDs: the EXIF IFD, the GPS IFD and (inside the EXIF IFD) the
//! interoperability IFD. [`read_ifd`] loads an IFD with those sub-IFDs into memory, [`write_ifd`] lays one out again
//! at the end of a buffer, and [`Ifd::convert`] changes its byte order. Only classic (32-bit offset) TIFF is handled.

use std::io::{Read, Seek, SeekFrom};

/// Tag of the pointer to the EXIF IFD.
pub const EXIF_IFD: u16 = 34665;
/// Tag of the pointer to the GPS IFD.
pub const GPS_IFD: u16 = 34853;
/// Tag of the pointer to the interoperability IFD (inside the EXIF IFD).
pub const INTEROP_IFD: u16 = 40965;
/// Field type of a pointer to an IFD (TIFF technical note 1); `LONG` (4) is used as well.
pub const TYPE_IFD: u16 = 13;
/// `LONG`.
pub const TYPE_LONG: u16 = 4;

/// Sub-IFDs nest at most this deep (IFD0 → EXIF → interoperability is 2).
const MAX_DEPTH: usize = 3;
/// Longest value read (ICC profiles and XMP packets can be large; nothing else comes near).
const MAX_VALUE: u64 = 64 << 20;

/// Byte order of a TIFF structure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Order {
    /// `II`
    Little,
    /// `MM`
    Big,
}

impl Order {
    pub fn u16(self, b: &[u8]) -> u16 {
        let b = [b[0], b[1]];
        match self {
            Order::Little => u16::from_le_bytes(b),
            Order::Big => u16::from_be_bytes(b),
        }
    }

    pub fn u32(self, b: &[u8]) -> u32 {
        let b = [b[0], b[1], b[2], b[3]];
        match self {
            Order::Little => u32::from_le_bytes(b),
            Order::Big => u32::from_be_bytes(b),
        }
    }

    pub fn put_u16(self, v: u16) -> [u8; 2] {
        match self {
            Order::Little => v.to_le_bytes(),
            Order::Big => v.to_be_bytes(),
        }
    }

    pub fn put_u32(self, v: u32) -> [u8; 4] {
        match self {
            Order::Little => v.to_le_bytes(),
            Order::Big => v.to_be_bytes(),
        }
    }

    /// The native order of this machine (the order the `tiff` crate writes).
    #[cfg(test)]
    pub fn native() -> Order {
        if cfg!(target_endian = "big") {
            Order::Big
        } else {
            Order::Little
        }
    }
}

/// Size in bytes of the unit that is byte-swapped within a value of field type `kind` (a `RATIONAL` is two
/// `LONG`s), and the size of one component. `None` for types classic TIFF does not define.
fn type_sizes(kind: u16) -> Option<(usize, usize)> {
    Some(match kind {
        1 | 2 | 6 | 7 => (1, 1),   // BYTE ASCII SBYTE UNDEFINED
        3 | 8 => (2, 2),           // SHORT SSHORT
        4 | 9 | 11 | 13 => (4, 4), // LONG SLONG FLOAT IFD
        5 | 10 => (4, 8),          // RATIONAL SRATIONAL
        12 => (8, 8),              // DOUBLE
        _ => return None,
    })
}

/// One entry of an IFD. `value` holds the value's bytes in the IFD's byte order, without padding.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    pub tag: u16,
    pub kind: u16,
    pub count: u32,
    pub value: Vec<u8>,
    /// For the pointer tags ([`EXIF_IFD`], [`GPS_IFD`], [`INTEROP_IFD`]): the IFD pointed to. Its offset is
    /// assigned when the IFD is written.
    pub sub: Option<Ifd>,
}

impl Entry {
    /// An entry holding `value` (in `order`'s byte order already, or single bytes).
    pub fn new(tag: u16, kind: u16, value: Vec<u8>) -> Entry {
        let component = type_sizes(kind).map_or(1, |(_, c)| c);
        Entry {
            tag,
            kind,
            count: (value.len() / component) as u32,
            value,
            sub: None,
        }
    }

    /// The value as an unsigned integer, for `BYTE`, `SHORT` and `LONG` entries of count 1.
    pub fn uint(&self, order: Order) -> Option<u32> {
        match (self.kind, self.value.len()) {
            (1, 1) => Some(self.value[0] as u32),
            (3, 2) => Some(order.u16(&self.value) as u32),
            (4 | 13, 4) => Some(order.u32(&self.value)),
            _ => None,
        }
    }
}

/// An IFD: entries in ascending tag order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Ifd {
    pub entries: Vec<Entry>,
}

impl Ifd {
    pub fn get(&self, tag: u16) -> Option<&Entry> {
        self.entries.iter().find(|e| e.tag == tag)
    }

    /// Insert `entry`, replacing an entry with the same tag, keeping tag order.
    pub fn set(&mut self, entry: Entry) {
        match self.entries.binary_search_by_key(&entry.tag, |e| e.tag) {
            Ok(i) => self.entries[i] = entry,
            Err(i) => self.entries.insert(i, entry),
        }
    }

    pub fn remove(&mut self, tag: u16) -> Option<Entry> {
        let i = self.entries.iter().position(|e| e.tag == tag)?;
        Some(self.entries.remove(i))
    }

    /// Re-encode every value (and every sub-IFD) from byte order `from` to `to`. `UNDEFINED` values (such as a
    /// maker note) are opaque and stay as they are.
    pub fn convert(&mut self, from: Order, to: Order) {
        if from == to {
            return;
        }
        for e in &mut self.entries {
            if let Some((unit, _)) = type_sizes(e.kind) {
                if unit > 1 {
                    for u in e.value.chunks_exact_mut(unit) {
                        u.reverse();
                    }
                }
            }
            if let Some(sub) = &mut e.sub {
                sub.convert(from, to);
            }
        }
    }
}

/// Random access to the bytes of a TIFF structure: a file or a buffer.
pub trait Source {
    fn len(&mut self) -> std::io::Result<u64>;
    fn read_at(&mut self, offset: u64, buf: &mut [u8]) -> std::io::Result<()>;
}

impl Source for &[u8] {
    fn len(&mut self) -> std::io::Result<u64> {
        Ok(<[u8]>::len(self) as u64)
    }

    fn read_at(&mut self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        let start = usize::try_from(offset).unwrap_or(usize::MAX);
        match start
            .checked_add(buf.len())
            .and_then(|end| self.get(start..end))
        {
            Some(b) => {
                buf.copy_from_slice(b);
                Ok(())
            }
            None => Err(std::io::ErrorKind::UnexpectedEof.into()),
        }
    }
}

/// A seekable reader as a [`Source`] (offsets are relative to `base`, where the TIFF header starts).
pub struct Reader<R> {
    pub inner: R,
    pub base: u64,
}

impl<R: Read + Seek> Source for Reader<R> {
    fn len(&mut self) -> std::io::Result<u64> {
        let end = self.inner.seek(SeekFrom::End(0))?;
        Ok(end.saturating_sub(self.base))
    }

    fn read_at(&mut self, offset: u64, buf: &mut [u8]) -> std::io::Result<()> {
        self.inner.seek(SeekFrom::Start(self.base + offset))?;
        self.inner.read_exact(buf)
    }
}

/// Byte order and offset of IFD0, from the 8-byte TIFF header.
pub fn read_header(src: &mut dyn Source) -> Result<(Order, u32), String> {
    let mut h = [0u8; 8];
    src.read_at(0, &mut h)
        .map_err(|_| "too short for a TIFF header".to_string())?;
    let order = match &h[..2] {
        b"II" => Order::Little,
        b"MM" => Order::Big,
        _ => return Err("no TIFF byte-order mark (II or MM)".into()),
    };
    match order.u16(&h[2..4]) {
        42 => Ok((order, order.u32(&h[4..8]))),
        43 => Err("BigTIFF (64-bit offsets) is not supported".into()),
        v => Err(format!("TIFF version {v}, expected 42")),
    }
}

/// Read the IFD at `offset` and, recursively, the sub-IFDs its pointer tags point to. `keep(depth, tag)` says
/// which entries to load (depth 0 is this IFD): values of other entries are not read. Entries that cannot be read
/// (value out of bounds, unknown type, broken sub-IFD) are left out and described in `problems`. Returns the IFD
/// and the offset of the next IFD in the chain (0 for none). Fails only when the IFD itself cannot be read.
pub fn read_ifd(
    src: &mut dyn Source,
    order: Order,
    offset: u32,
    keep: &dyn Fn(usize, u16) -> bool,
    problems: &mut Vec<String>,
) -> Result<(Ifd, u32), String> {
    let mut walk = IfdWalk {
        src,
        order,
        keep,
        problems,
        visited: vec![offset],
    };
    walk.ifd_at(offset, 0)
}

/// What travels down the recursive read of an IFD and its sub-IFDs (see [`read_ifd`]).
struct IfdWalk<'a, 's> {
    src: &'a mut (dyn Source + 's),
    order: Order,
    keep: &'a dyn Fn(usize, u16) -> bool,
    problems: &'a mut Vec<String>,
    /// Offsets of the IFDs read so far: a pointer back to one of them is a loop.
    visited: Vec<u32>,
}

impl IfdWalk<'_, '_> {
    /// The IFD at `offset`, `depth` levels below the first, and the offset of the next IFD in its chain.
    fn ifd_at(&mut self, offset: u32, depth: usize) -> Result<(Ifd, u32), String> {
        let order = self.order;
        let len = self.src.len().map_err(|e| e.to_string())?;
        let mut n = [0u8; 2];
        self.src
            .read_at(offset as u64, &mut n)
            .map_err(|_| format!("IFD at offset {offset} lies past the end ({len} bytes)"))?;
        let count = order.u16(&n) as usize;
        let mut table = vec![0u8; count * 12 + 4];
        self.src
            .read_at(offset as u64 + 2, &mut table)
            .map_err(|_| format!("IFD at offset {offset} with {count} entries is cut off"))?;
        let next = order.u32(&table[count * 12..]);
        let mut ifd = Ifd::default();
        for raw in table[..count * 12].chunks_exact(12) {
            if let Some(entry) = self.entry(raw, depth, len) {
                ifd.set(entry);
            }
        }
        Ok((ifd, next))
    }

    /// The entry `raw` (12 bytes of an IFD at `depth`; the source is `len` bytes) with its value and, for a
    /// pointer tag, its sub-IFD. `None` when `keep` does not want it, or when it cannot be read (the reason in
    /// `problems`).
    fn entry(&mut self, raw: &[u8], depth: usize, len: u64) -> Option<Entry> {
        let order = self.order;
        let tag = order.u16(&raw[0..2]);
        if !(self.keep)(depth, tag) {
            return None;
        }
        let kind = order.u16(&raw[2..4]);
        let n = order.u32(&raw[4..8]);
        let Some((_, component)) = type_sizes(kind) else {
            self.problems.push(format!(
                "tag {tag:#06x} has unknown field type {kind}; left out"
            ));
            return None;
        };
        let size = n as u64 * component as u64;
        let value = self.value(raw, tag, size, len)?;
        let mut entry = Entry {
            tag,
            kind,
            count: n,
            value,
            sub: None,
        };
        if matches!(tag, EXIF_IFD | GPS_IFD | INTEROP_IFD) {
            entry.sub = Some(self.sub_ifd(&entry, depth)?);
        }
        Some(entry)
    }

    /// The `size`-byte value of entry `raw` (tag `tag`): in the entry itself up to four bytes, else at the offset
    /// it holds. `None` when it lies past the end or cannot be read (the reason in `problems`).
    fn value(&mut self, raw: &[u8], tag: u16, size: u64, len: u64) -> Option<Vec<u8>> {
        if size <= 4 {
            return Some(raw[8..8 + size as usize].to_vec());
        }
        let at = self.order.u32(&raw[8..12]) as u64;
        if size > MAX_VALUE || at + size > len {
            self.problems.push(format!(
                "tag {tag:#06x}: {size}-byte value at offset {at} lies past the end ({len} bytes); left out"
            ));
            return None;
        }
        let mut v = vec![0u8; size as usize];
        if let Err(e) = self.src.read_at(at, &mut v) {
            self.problems.push(format!("tag {tag:#06x}: {e}; left out"));
            return None;
        }
        Some(v)
    }

    /// The sub-IFD that the pointer `entry` (in an IFD at `depth`) points to. `None` when the pointer is not a
    /// valid offset, leads back to an IFD already read or too deep, or the sub-IFD cannot be read (the reason in
    /// `problems`).
    fn sub_ifd(&mut self, entry: &Entry, depth: usize) -> Option<Ifd> {
        let (tag, kind) = (entry.tag, entry.kind);
        let Some(at) = entry
            .uint(self.order)
            .filter(|_| matches!(kind, TYPE_LONG | TYPE_IFD))
        else {
            self.problems.push(format!(
                "tag {tag:#06x} is not a valid IFD pointer; left out"
            ));
            return None;
        };
        if depth + 1 >= MAX_DEPTH || self.visited.contains(&at) {
            self.problems.push(format!(
                "tag {tag:#06x} points to a loop or too deep; left out"
            ));
            return None;
        }
        self.visited.push(at);
        match self.ifd_at(at, depth + 1) {
            Ok((sub, _)) => Some(sub),
            Err(e) => {
                self.problems
                    .push(format!("sub-IFD of tag {tag:#06x}: {e}; left out"));
                None
            }
        }
    }
}

fn pad_to_word(out: &mut Vec<u8>) {
    if out.len() % 2 == 1 {
        out.push(0);
    }
}

fn offset32(pos: usize) -> Result<u32, String> {
    u32::try_from(pos)
        .map_err(|_| "TIFF structure exceeds 4 GiB (classic TIFF offsets are 32-bit)".to_string())
}

/// Append `ifd` (and its sub-IFDs and long values) to `out`, whose byte 0 is the TIFF header, with `next` as the
/// offset of the next IFD in the chain. Returns the offset of the IFD.
pub fn write_ifd(out: &mut Vec<u8>, order: Order, ifd: &Ifd, next: u32) -> Result<u32, String> {
    pad_to_word(out);
    let start = out.len();
    let count = u16::try_from(ifd.entries.len())
        .map_err(|_| "more than 65535 tags in one IFD".to_string())?;
    out.extend_from_slice(&order.put_u16(count));
    out.resize(start + 2 + 12 * ifd.entries.len(), 0);
    out.extend_from_slice(&order.put_u32(next));
    let mut sorted: Vec<&Entry> = ifd.entries.iter().collect();
    sorted.sort_by_key(|e| e.tag);
    for (i, e) in sorted.into_iter().enumerate() {
        let mut field = [0u8; 4];
        let count = if let Some(sub) = &e.sub {
            field = order.put_u32(write_ifd(out, order, sub, 0)?);
            1
        } else if e.value.len() <= 4 {
            field[..e.value.len()].copy_from_slice(&e.value);
            e.count
        } else {
            pad_to_word(out);
            field = order.put_u32(offset32(out.len())?);
            out.extend_from_slice(&e.value);
            e.count
        };
        let at = start + 2 + 12 * i;
        out[at..at + 2].copy_from_slice(&order.put_u16(e.tag));
        out[at + 2..at + 4].copy_from_slice(&order.put_u16(e.kind));
        out[at + 4..at + 8].copy_from_slice(&order.put_u32(count));
        out[at + 8..at + 12].copy_from_slice(&field);
    }
    offset32(start)
}

/// A complete TIFF structure (header and `ifd0`): the layout of an EXIF block.
pub fn write_tiff(order: Order, ifd0: &Ifd) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    out.extend_from_slice(match order {
        Order::Little => b"II",
        Order::Big => b"MM",
    });
    out.extend_from_slice(&order.put_u16(42));
    out.extend_from_slice(&order.put_u32(8));
    write_ifd(&mut out, order, ifd0, 0)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(order: Order) -> Ifd {
        let mut gps = Ifd::default();
        // GPSLatitude: three RATIONALs.
        let mut lat = Vec::new();
        for (n, d) in [(12u32, 1u32), (34, 1), (5678, 100)] {
            lat.extend_from_slice(&order.put_u32(n));
            lat.extend_from_slice(&order.put_u32(d));
        }
        gps.set(Entry::new(2, 5, lat));
        gps.set(Entry::new(1, 2, b"N\0".to_vec()));
        let mut exif = Ifd::default();
        exif.set(Entry::new(0x9003, 2, b"2024:05:06 07:08:09\0".to_vec()));
        exif.set(Entry::new(0x927c, 7, vec![1, 2, 3, 4, 5, 6, 7]));
        let mut ifd0 = Ifd::default();
        ifd0.set(Entry::new(272, 2, b"SeaCam 3000\0".to_vec()));
        ifd0.set(Entry::new(274, 3, order.put_u16(6).to_vec()));
        ifd0.set(Entry {
            sub: Some(exif),
            ..Entry::new(EXIF_IFD, TYPE_LONG, vec![0; 4])
        });
        ifd0.set(Entry {
            sub: Some(gps),
            ..Entry::new(GPS_IFD, TYPE_LONG, vec![0; 4])
        });
        ifd0
    }

    /// Pointer values are layout-dependent; compare IFDs without them.
    fn normalise(mut ifd: Ifd) -> Ifd {
        for e in &mut ifd.entries {
            if let Some(sub) = e.sub.take() {
                e.value = vec![0; 4];
                e.sub = Some(normalise(sub));
            }
        }
        ifd
    }

    #[test]
    fn write_then_read_gives_the_same_tree_in_both_orders() {
        for order in [Order::Little, Order::Big] {
            let ifd0 = sample(order);
            let blob = write_tiff(order, &ifd0).unwrap();
            let mut src: &[u8] = &blob;
            let (o, at) = read_header(&mut src).unwrap();
            assert_eq!((o, at), (order, 8));
            let mut problems = Vec::new();
            let (back, next) = read_ifd(&mut src, o, at, &|_, _| true, &mut problems).unwrap();
            assert!(problems.is_empty(), "{problems:?}");
            assert_eq!(next, 0);
            assert_eq!(normalise(back), ifd0);
            // Every value offset is even (word-aligned), as TIFF requires.
            assert_eq!(blob.len() % 2, 0);
        }
    }

    #[test]
    fn byte_order_conversion_swaps_numbers_not_bytes_or_text() {
        let mut big = sample(Order::Big);
        big.convert(Order::Big, Order::Little);
        assert_eq!(big, sample(Order::Little));
        let exif = big.get(EXIF_IFD).unwrap().sub.as_ref().unwrap();
        assert_eq!(exif.get(0x927c).unwrap().value, [1, 2, 3, 4, 5, 6, 7]);
    }

    #[test]
    fn hand_made_little_endian_ifd_is_read() {
        // Header, IFD0 at 8 with one SHORT (Orientation = 3) and one out-of-line ASCII (Make = "ABCDEFG").
        let mut b = b"II\x2a\x00\x08\x00\x00\x00".to_vec();
        b.extend_from_slice(&[2, 0]);
        b.extend_from_slice(&[0x0f, 0x01, 2, 0, 8, 0, 0, 0, 38, 0, 0, 0]);
        b.extend_from_slice(&[0x12, 0x01, 3, 0, 1, 0, 0, 0, 3, 0, 0, 0]);
        b.extend_from_slice(&[0, 0, 0, 0]);
        b.extend_from_slice(b"ABCDEFG\0");
        let mut src: &[u8] = &b;
        let mut problems = Vec::new();
        let (ifd, _) = read_ifd(&mut src, Order::Little, 8, &|_, _| true, &mut problems).unwrap();
        assert_eq!(ifd.get(271).unwrap().value, b"ABCDEFG\0");
        assert_eq!(ifd.get(274).unwrap().uint(Order::Little), Some(3));
        // Only the wanted tags are loaded.
        let (ifd, _) =
            read_ifd(&mut src, Order::Little, 8, &|_, t| t == 274, &mut problems).unwrap();
        assert_eq!(ifd.entries.len(), 1);
    }

    #[test]
    fn broken_entries_are_left_out_with_a_reason() {
        let mut b = b"MM\x00\x2a\x00\x00\x00\x08".to_vec();
        b.extend_from_slice(&[0, 3]);
        // Make: 200 bytes at offset 4000 (past the end).
        b.extend_from_slice(&[0x01, 0x0f, 0, 2, 0, 0, 0, 200, 0, 0, 0x0f, 0xa0]);
        // EXIF pointer to itself (a loop).
        b.extend_from_slice(&[0x87, 0x69, 0, 4, 0, 0, 0, 1, 0, 0, 0, 8]);
        // Model: fine.
        b.extend_from_slice(&[0x01, 0x10, 0, 2, 0, 0, 0, 2, b'X', 0, 0, 0]);
        b.extend_from_slice(&[0, 0, 0, 0]);
        let mut src: &[u8] = &b;
        let mut problems = Vec::new();
        let (ifd, _) = read_ifd(&mut src, Order::Big, 8, &|_, _| true, &mut problems).unwrap();
        assert_eq!(ifd.entries.len(), 1);
        assert_eq!(ifd.get(272).unwrap().value, b"X\0");
        assert_eq!(problems.len(), 2, "{problems:?}");
        assert!(
            problems[0].contains("0x010f") && problems[1].contains("0x8769"),
            "{problems:?}"
        );
        // An IFD offset past the end is an error.
        assert!(read_ifd(&mut src, Order::Big, 1000, &|_, _| true, &mut problems).is_err());
        let mut short: &[u8] = b"II*";
        assert!(read_header(&mut short).is_err());
        let mut big: &[u8] = b"II\x2b\x00\x08\x00\x00\x00";
        assert!(read_header(&mut big).unwrap_err().contains("BigTIFF"));
    }
}
