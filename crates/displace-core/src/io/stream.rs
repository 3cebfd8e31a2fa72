//! The streamed distance-map writer: a bake hands it slabs of depth slices
//! ([`crate::bake_streamed`]) and it encodes each in parallel (or, for r8
//! once the range is known, takes the codes the bake encoded as it computed
//! them, [`SlabSink::encoder`]) and appends it to the output file, so that a
//! bake's peak memory is the height map and a slab or two rather than the
//! volume in `f32` next to its encoding. The file
//! lives under a temporary name ([`super::atomic::AtomicFile`]) until
//! [`MapStream::finish`]; an error or an interruption leaves nothing.
//!
//! The bytes are those of [`super::write_distance_map`] on the in-memory map
//! (tests/stream.rs checks it file for file). Where a header depends on the
//! whole volume, the writer holds what it must: a KTX2 header states the r8
//! range, which comes from the volume's minimum, so slabs are held (as `f32`)
//! until the slabs still to come cannot lower it ([`crate::Slab`] carries a
//! lower bound on them, which the bake makes tight from what it has computed,
//! so that the first slab settles it but for a minimum within a rounding of a
//! 1/64 step); a KTX2 r16f header states the largest rounding, known only at
//! the end, so its level data (the output's size) is held until then.

use super::atomic::AtomicFile;
use super::{dds, ktx2, FormatError, MapFile};
use crate::distance_map::{f16_round_down, Format, R8Encoder, R8Range};
use crate::{BakeLayout, CodedSlab, Error, Extent, Result, Slab, SlabSink};
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

/// Values encoded per parallel task.
const CHUNK: usize = 1 << 16;

/// Outputs of at least this many bytes are written past the page cache
/// ([`super::direct`]). Below it the page cache is cheap and direct writes,
/// synchronous with the device, are not: a 16 MB map (512x512x64 r8) took
/// 0.095 s at best direct against 0.082 s buffered (15 runs each), while a
/// 268 MB one was 10-13% faster direct and a 512 MB one 26%.
const DIRECT_FROM_BYTES: u64 = 64 << 20;

/// The bytes of a `size` map's voxels in `format` (saturating: a size
/// whose product does not fit is more than any disk).
fn output_bytes(size: [usize; 3], format: Format) -> u64 {
    size.iter().fold(format.bytes_per_voxel() as u64, |b, &n| {
        b.saturating_mul(n as u64)
    })
}

/// A distance-map file being written slab by slab.
pub struct MapStream {
    path: PathBuf,
    out: Background,
    kind: MapFile,
    format: Format,
    size: [usize; 3],
    extent: Extent,
    layout: Option<BakeLayout>,
    /// Lowest value pushed so far.
    lo: f32,
    /// KTX2 (r8, r32f): values held until the header can be written.
    held: Vec<f32>,
    header_written: bool,
    /// KTX2 r16f: the level data, held until the end, and the largest
    /// rounding so far.
    level16: Vec<u8>,
    extra: f32,
    voxels: usize,
}

impl MapStream {
    /// Checks that a `size` map in `format` can be written to `path` (the
    /// file type its extension names) and creates its temporary file, all
    /// before any work: a missing or unwritable directory fails here.
    pub fn create(path: &Path, format: Format, size: [usize; 3], extent: Extent) -> Result<Self> {
        let direct = output_bytes(size, format) >= DIRECT_FROM_BYTES;
        Self::create_writing(path, format, size, extent, direct)
    }

    /// [`Self::create`], choosing whether to write past the page cache
    /// (`direct`, where the file system allows it) rather than by the
    /// output's size: the same bytes either way, which the tests check on
    /// maps too small for [`Self::create`] to choose it.
    pub fn create_writing(
        path: &Path,
        format: Format,
        size: [usize; 3],
        extent: Extent,
        direct: bool,
    ) -> Result<Self> {
        let kind = MapFile::from_path(path)?;
        let refuse = |e: FormatError| e.at(path);
        match kind {
            MapFile::Npy if format != Format::R32F => {
                return Err(Error::Format {
                    path: path.to_path_buf(),
                    message: format!(
                        "npy stores float32 in physical units; format {} applies only to .ktx2 and .dds",
                        format.name()
                    ),
                })
            }
            MapFile::Dds => dds::check_size(size, format).map_err(refuse)?,
            MapFile::Ktx2 if size.iter().any(|&n| n > u32::MAX as usize) => {
                return Err(refuse(FormatError::Unsupported(format!(
                    "{}x{}x{} exceeds KTX2's 32-bit sizes",
                    size[0], size[1], size[2]
                ))))
            }
            _ => {}
        }
        // The voxels' bytes; the header is small enough to ride on any
        // rounding of the file system's own accounting.
        super::atomic::check_free_space(path, output_bytes(size, format))?;
        Ok(Self {
            path: path.to_path_buf(),
            out: Background::start(
                AtomicFile::create(path)?,
                direct,
                crate::memory::writer_slices(size[0].saturating_mul(size[1])) - 1,
            ),
            kind,
            format,
            size,
            extent,
            layout: None,
            lo: f32::INFINITY,
            held: Vec::new(),
            header_written: false,
            level16: Vec::new(),
            extra: 0.0,
            voxels: 0,
        })
    }

    /// Writes what is still held and moves the file into place (or stages
    /// it in the open [`super::atomic::Batch`]).
    pub fn finish(mut self) -> Result<()> {
        let [w, h, d] = self.size;
        if self.voxels != w * h * d || self.layout.is_none() {
            return Err(Error::InvalidSize(format!(
                "{} of {} voxels were baked into {}",
                self.voxels,
                w * h * d,
                self.path.display()
            )));
        }
        if self.kind == MapFile::Ktx2 {
            if self.format == Format::R16F {
                let level = std::mem::take(&mut self.level16);
                self.write_ktx2_header()?;
                self.send(level)?;
            } else if !self.header_written {
                self.write_ktx2_header()?;
                let held = std::mem::take(&mut self.held);
                self.encode_and_write(&held)?;
            }
        }
        self.out
            .finish()
            .map_err(|source| Error::Io {
                path: self.path.clone(),
                source,
            })?
            .commit()
    }

    /// The KTX2 header for the volume's minimum `self.lo` (and, for r16f,
    /// the largest rounding): the very scalars [`super::ktx2::to_bytes`]
    /// finds through [`crate::DistanceMap::quantized`].
    fn write_ktx2_header(&mut self) -> Result<()> {
        let layout = self.layout.ok_or_else(|| {
            Error::InvalidSize("a slab was pushed before the stream was begun".into())
        })?;
        // `DistanceMap::from_raw` then `data_underestimate`.
        let range = R8Range::for_min(self.lo);
        let data_underestimate = (layout.underestimate + range.quantum()) - range.quantum();
        // `quantized`: the rounded map's bound, and its own range's quantum.
        let (extra, rounded_lo, r8) = match self.format {
            Format::R32F => (0.0, self.lo, None),
            Format::R16F => (self.extra, f16_round_down(self.lo).to_f32(), None),
            Format::R8 => (
                range.quantum(),
                range.decode(range.encode(self.lo)),
                Some(range),
            ),
        };
        let q = R8Range::for_min(rounded_lo).quantum();
        let underestimate = ((data_underestimate + extra) + q) - q;
        let head = ktx2::header(
            self.size,
            layout.address,
            underestimate,
            self.extent,
            self.format,
            r8,
            &[],
        );
        self.header_written = true;
        self.write(&head)
    }

    /// Encodes and writes `values` a depth slice at a time, so that the
    /// buffers in flight are slices, not slabs.
    fn encode_and_write(&mut self, values: &[f32]) -> Result<()> {
        let slice = (self.size[0] * self.size[1]).max(1);
        values
            .chunks(slice)
            .try_for_each(|values| self.encode_slice(values))
    }

    fn encode_slice(&mut self, values: &[f32]) -> Result<()> {
        let mut bytes = self.out.buffer();
        let bpv = self.format.bytes_per_voxel();
        bytes.resize(values.len() * bpv, 0);
        match (self.kind, self.format) {
            (MapFile::Npy, _) => {
                let sz = self.extent.sz;
                encode(values, 4, &mut bytes, |v, o| {
                    o.copy_from_slice(&(v * sz).to_le_bytes());
                    0.0
                });
            }
            (_, Format::R32F) => {
                encode(values, 4, &mut bytes, |v, o| {
                    o.copy_from_slice(&v.to_le_bytes());
                    0.0
                });
            }
            (_, Format::R16F) => {
                encode(values, 2, &mut bytes, |v, o| {
                    o.copy_from_slice(&f16_round_down(v).to_le_bytes());
                    0.0
                });
            }
            (kind, Format::R8) => {
                let range = if kind == MapFile::Dds {
                    dds::check_r8_min(self.lo).map_err(|e| e.at(&self.path))?;
                    dds::DDS_R8_RANGE
                } else {
                    R8Range::for_min(self.lo)
                };
                let encoder = range.encoder();
                bytes
                    .par_chunks_mut(CHUNK)
                    .zip(values.par_chunks(CHUNK))
                    .for_each(|(c, v)| encoder.encode_into(v, c));
            }
        }
        self.send(bytes)
    }

    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        let mut buf = self.out.buffer();
        buf.clear();
        buf.extend_from_slice(bytes);
        self.send(buf)
    }

    fn send(&mut self, bytes: Vec<u8>) -> Result<()> {
        self.out.send(bytes).map_err(|source| Error::Io {
            path: self.path.clone(),
            source,
        })
    }
}

impl SlabSink for MapStream {
    /// Takes the bake's layout and writes what header it can.
    fn begin(&mut self, layout: BakeLayout) -> Result<()> {
        if layout.size != self.size {
            return Err(Error::InvalidSize(format!(
                "the bake is {:?} but the file was opened for {:?}",
                layout.size, self.size
            )));
        }
        self.layout = Some(layout);
        let [w, h, d] = self.size;
        match self.kind {
            MapFile::Npy => {
                let head = super::npy::header("<f4", &[d, h, w]);
                self.write(&head)?;
                self.header_written = true;
            }
            MapFile::Dds => {
                let head = dds::header(self.size, self.format).map_err(|e| e.at(&self.path))?;
                self.write(&head)?;
                self.header_written = true;
            }
            // The held r16f level, allocated once: grown by doubling it
            // would pass through twice its size.
            MapFile::Ktx2 if self.format == Format::R16F => {
                self.level16.reserve_exact(2 * w * h * d);
            }
            MapFile::Ktx2 => {}
        }
        Ok(())
    }

    /// Encodes and writes (or holds) one slab.
    fn push(&mut self, slab: Slab<'_>) -> Result<()> {
        let values = slab.values;
        self.voxels += values.len();
        self.lo = self.lo.min(slab.min);
        match (self.kind, self.format) {
            (MapFile::Ktx2, Format::R16F) => {
                let start = self.level16.len();
                self.level16.resize(start + 2 * values.len(), 0);
                let extra = encode(values, 2, &mut self.level16[start..], |v, o| {
                    let q = f16_round_down(v);
                    o.copy_from_slice(&q.to_le_bytes());
                    v - q.to_f32()
                });
                self.extra = self.extra.max(extra);
                Ok(())
            }
            (MapFile::Ktx2, _) if !self.header_written => {
                let settled = self.lo.is_finite()
                    && R8Range::for_min(self.lo)
                        == R8Range::for_min(self.lo.min(slab.rest_lower_bound));
                if settled {
                    // Written straight from the slab: usually the first one
                    // settles the range, and nothing is ever held.
                    self.write_ktx2_header()?;
                    let held = std::mem::take(&mut self.held);
                    self.encode_and_write(&held)?;
                    self.encode_and_write(values)
                } else {
                    self.held.extend_from_slice(values);
                    Ok(())
                }
            }
            _ => self.encode_and_write(values),
        }
    }

    /// R8 files once their range is known: a KTX2 file's when its header
    /// is written (the range settled), a DDS file's (fixed) from the start.
    fn encoder(&self) -> Option<R8Encoder> {
        match (self.kind, self.format) {
            (MapFile::Ktx2, Format::R8) if self.header_written => {
                Some(R8Range::for_min(self.lo).encoder())
            }
            (MapFile::Dds, Format::R8) => Some(dds::DDS_R8_RANGE.encoder()),
            _ => None,
        }
    }

    fn code_buffer(&mut self) -> Vec<u8> {
        self.out.buffer()
    }

    /// Writes a slab's codes, after checking that its values leave the
    /// range they were encoded for as it was (the bake checks its own
    /// promise; this is the file's).
    fn push_codes(&mut self, slab: CodedSlab) -> Result<()> {
        let range = R8Range::for_min(self.lo);
        self.voxels += slab.codes.len();
        self.lo = self.lo.min(slab.min);
        match self.kind {
            MapFile::Dds => dds::check_r8_min(self.lo).map_err(|e| e.at(&self.path))?,
            _ if R8Range::for_min(self.lo) != range => {
                return Err(Error::Invariant(format!(
                    "depth slices from {} reach {}, below the r8 range already written to {}",
                    slab.first,
                    slab.min,
                    self.path.display()
                )))
            }
            _ => {}
        }
        self.send(slab.codes)
    }
}

/// The file's writer on a thread of its own, so that the next slab is
/// computed while this one goes to the kernel (a tenth of a bake's time was
/// the copy into the page cache). Buffers come back for reuse. Beside the
/// one being written, the writer queues at most `queued` buffers
/// ([`crate::memory::writer_slices`]): one for small slices, so that a
/// bake's thread hands its slice over without waiting for the writer to
/// wake; none for large ones, whose hand-over is a rendezvous, a slice of
/// memory counting more there than a wake-up.
struct Background {
    tx: Option<SyncSender<Vec<u8>>>,
    spare: Receiver<Vec<u8>>,
    thread: Option<JoinHandle<std::io::Result<AtomicFile>>>,
}

impl Background {
    /// The writer thread of `file`, writing past the page cache when
    /// `direct` and the file system allows it.
    fn start(mut file: AtomicFile, direct: bool, queued: usize) -> Self {
        let (tx, rx) = sync_channel::<Vec<u8>>(queued);
        let (back, spare) = sync_channel::<Vec<u8>>(8);
        let thread = std::thread::spawn(move || {
            // Past the page cache where the file system allows it
            // (`super::direct`: a fifth of a bake's CPU time was the copy
            // into it), else through it; the same bytes either way.
            let mut direct = if direct { file.direct_append() } else { None };
            for bytes in rx {
                match direct.as_mut().map(|d| d.append(&bytes)) {
                    Some(Ok(())) => {}
                    Some(Err(e)) => {
                        let d = direct.take().expect("matched Some");
                        if !d.untouched() {
                            return Err(e);
                        }
                        // Refused at the first write: write it all the
                        // ordinary way.
                        file.writer().write_all(d.held())?;
                        file.writer().write_all(&bytes)?;
                    }
                    None => {
                        file.writer().write_all(&bytes)?;
                        file.start_writeback()?;
                    }
                }
                let _ = back.try_send(bytes);
            }
            if let Some(d) = direct {
                d.finish()?;
            }
            Ok(file)
        });
        Self {
            tx: Some(tx),
            spare,
            thread: Some(thread),
        }
    }

    /// A buffer to fill: one written already, or a new one.
    fn buffer(&self) -> Vec<u8> {
        self.spare.try_recv().unwrap_or_default()
    }

    fn send(&mut self, bytes: Vec<u8>) -> std::io::Result<()> {
        let sent = self.tx.as_ref().is_some_and(|tx| tx.send(bytes).is_ok());
        if sent {
            Ok(())
        } else {
            // The writer stopped: its error says why.
            Err(self
                .join()
                .err()
                .unwrap_or_else(|| std::io::Error::other("the writer thread stopped")))
        }
    }

    fn join(&mut self) -> std::io::Result<AtomicFile> {
        self.tx = None;
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(std::io::Error::other("the writer thread panicked")),
            None => Err(std::io::Error::other("the writer thread stopped")),
        }
    }

    /// Waits for every byte to be written and returns the file.
    fn finish(mut self) -> std::io::Result<AtomicFile> {
        self.join()
    }
}

impl Drop for Background {
    fn drop(&mut self) {
        // Unfinished (an error, an interruption): the thread ends, and its
        // file, dropped uncommitted, is removed.
        if self.thread.is_some() {
            let _ = self.join();
        }
    }
}

/// `put(value, bytes)` for every value, `bpv` bytes each, in parallel;
/// returns the largest of what `put` returns (0 at least).
fn encode(
    values: &[f32],
    bpv: usize,
    out: &mut [u8],
    put: impl Fn(f32, &mut [u8]) -> f32 + Sync,
) -> f32 {
    out.par_chunks_mut(CHUNK * bpv)
        .zip(values.par_chunks(CHUNK))
        .map(|(o, v)| {
            o.chunks_exact_mut(bpv)
                .zip(v)
                .fold(0.0f32, |m, (o, &v)| m.max(put(v, o)))
        })
        .reduce(|| 0.0, f32::max)
}
