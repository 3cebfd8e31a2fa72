//! Appending a large file past the page cache (`O_DIRECT`), for the
//! streamed distance-map writer.
//!
//! Why: a bake's output (268 MB for a 2048x2048x64 r8 map, 2 GiB at 8K) is
//! written once and read later, if at all, by another process; copying it
//! into the page cache first was a fifth of a bake's CPU time on the
//! development VM, whose page cache is slow to fault in (`dd` of 268 MB:
//! 1.71 s cold, 0.13-0.15 s with `O_DIRECT`; BENCHMARKS.md). Direct I/O
//! asks that the buffer's address, the file offset and the length be
//! multiples of the device's block size: bytes are gathered into an aligned
//! buffer and written a whole buffer at a time, the tail padded to a block
//! and the file then cut to its length. Where a file system refuses direct
//! I/O (tmpfs), [`DirectAppend::open`] says so and the caller writes
//! through the page cache as before; the bytes on disk are the same.

use std::fs::File;
use std::io::Write;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;

/// Alignment of the buffer, offsets and lengths: a multiple of every
/// logical block size Linux file systems use (512 or 4096 bytes).
const BLOCK: usize = 4096;

/// Bytes gathered before each direct write (a whole number of blocks).
pub const DIRECT_BUFFER_BYTES: usize = 1 << 22;

/// One block of the aligned buffer.
#[derive(Clone, Copy)]
#[repr(C, align(4096))]
struct Block([u8; BLOCK]);

/// A file opened for direct writes at its start, and the bytes not yet
/// written (fewer than [`DIRECT_BUFFER_BYTES`]).
pub struct DirectAppend {
    file: File,
    blocks: Vec<Block>,
    len: usize,
    written: u64,
}

impl DirectAppend {
    /// Opens the (empty) file at `path` for direct writes; `None` where the
    /// file system does not take them.
    pub fn open(path: &Path) -> Option<Self> {
        let file = std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_DIRECT)
            .open(path)
            .ok()?;
        Some(Self {
            file,
            blocks: vec![Block([0; BLOCK]); DIRECT_BUFFER_BYTES / BLOCK],
            len: 0,
            written: 0,
        })
    }

    /// Nothing has reached the file yet (what is held is [`Self::held`]):
    /// a caller may still give up on direct writes and write through the
    /// page cache instead.
    pub fn untouched(&self) -> bool {
        self.written == 0
    }

    /// The bytes taken but not yet written.
    pub fn held(&self) -> &[u8] {
        &as_bytes(&self.blocks)[..self.len]
    }

    /// Takes `bytes`, writing every buffer that fills. An error on the
    /// first write (`EINVAL`: the file system took the flag at open but
    /// not the write) leaves the file untouched and [`Self::held`] what
    /// the calls before this one gave, so the caller can write that and
    /// `bytes` another way.
    pub fn append(&mut self, mut bytes: &[u8]) -> std::io::Result<()> {
        while !bytes.is_empty() {
            let len = self.len;
            let n = bytes.len().min(DIRECT_BUFFER_BYTES - len);
            as_bytes_mut(&mut self.blocks)[len..len + n].copy_from_slice(&bytes[..n]);
            self.len += n;
            bytes = &bytes[n..];
            if self.len == DIRECT_BUFFER_BYTES {
                if let Err(e) = (&self.file).write_all(as_bytes(&self.blocks)) {
                    self.len -= n;
                    return Err(e);
                }
                self.written += DIRECT_BUFFER_BYTES as u64;
                self.len = 0;
            }
        }
        Ok(())
    }

    /// Writes what is held (padded to a whole block) and cuts the file to
    /// the bytes taken.
    pub fn finish(mut self) -> std::io::Result<()> {
        let len = self.len;
        let padded = len.div_ceil(BLOCK) * BLOCK;
        as_bytes_mut(&mut self.blocks)[len..padded].fill(0);
        (&self.file).write_all(&as_bytes(&self.blocks)[..padded])?;
        self.file.set_len(self.written + len as u64)
    }
}

/// The blocks as the bytes they hold.
fn as_bytes(blocks: &[Block]) -> &[u8] {
    // SAFETY: `Block` is `repr(C)` around a byte array with no padding
    // (its size is its alignment), so the blocks are `len * BLOCK`
    // initialised, contiguous bytes, borrowed as long as `blocks`.
    unsafe {
        std::slice::from_raw_parts(blocks.as_ptr().cast::<u8>(), std::mem::size_of_val(blocks))
    }
}

/// [`as_bytes`], mutably.
fn as_bytes_mut(blocks: &mut [Block]) -> &mut [u8] {
    // SAFETY: as in `as_bytes`; every byte pattern is a valid `Block`.
    unsafe {
        std::slice::from_raw_parts_mut(
            blocks.as_mut_ptr().cast::<u8>(),
            std::mem::size_of_val(blocks),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bytes that differ from position to position and from run to run of
    /// the pattern, so a misplaced block would show.
    fn pattern(n: usize, seed: u8) -> Vec<u8> {
        (0..n)
            .map(|i| (i as u32).wrapping_mul(2_654_435_761).to_le_bytes()[3] ^ seed)
            .collect()
    }

    #[test]
    fn appended_bytes_land_exactly_whatever_the_pieces() {
        let dir = tempfile::tempdir().unwrap();
        for (k, pieces) in [
            vec![0usize],
            vec![1],
            vec![BLOCK - 1, 1, BLOCK + 1],
            vec![DIRECT_BUFFER_BYTES],
            vec![DIRECT_BUFFER_BYTES - 7, 7, 3 * DIRECT_BUFFER_BYTES + 12_345],
            vec![
                128,
                5 * BLOCK,
                DIRECT_BUFFER_BYTES / 2,
                DIRECT_BUFFER_BYTES,
                17,
            ],
        ]
        .into_iter()
        .enumerate()
        {
            let path = dir.path().join(format!("f{k}"));
            std::fs::write(&path, b"").unwrap();
            let mut want = Vec::new();
            match DirectAppend::open(&path) {
                Some(mut d) => {
                    for (j, &n) in pieces.iter().enumerate() {
                        let p = pattern(n, j as u8);
                        d.append(&p).unwrap();
                        want.extend_from_slice(&p);
                    }
                    d.finish().unwrap();
                }
                // A file system without direct I/O: nothing to check here.
                None => return,
            }
            assert_eq!(std::fs::read(&path).unwrap(), want, "pieces {pieces:?}");
        }
    }
}
