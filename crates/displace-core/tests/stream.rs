//! The streamed bake ([`bake_streamed`] into [`MapStream`]) writes the very
//! bytes of the in-memory bake and [`write_distance_map`], for every file
//! type, format and addressing, whatever the slab size; and a stream that is
//! dropped or fails leaves no file.

use displace_core::distance_map::Format;
use displace_core::generators::generate;
use displace_core::io::stream::MapStream;
use displace_core::io::write_distance_map;
use displace_core::{
    bake, bake_streamed, Address, BakeLayout, BakeOptions, CodedSlab, Extent, Slab, SlabSink,
};
use std::path::Path;

fn streamed(
    height: &displace_core::HeightMap,
    opts: &BakeOptions,
    path: &Path,
    format: Format,
    slab: usize,
) {
    let mut stream = MapStream::create(path, format, opts.size, opts.extent).unwrap();
    bake_streamed(height, opts, slab, &mut stream).unwrap();
    stream.finish().unwrap();
    // Past the page cache (O_DIRECT where the file system takes it, as for
    // large maps): the same bytes.
    let direct = path.with_extension(format!(
        "direct.{}",
        path.extension().unwrap().to_str().unwrap()
    ));
    let mut stream =
        MapStream::create_writing(&direct, format, opts.size, opts.extent, true).unwrap();
    bake_streamed(height, opts, slab, &mut stream).unwrap();
    stream.finish().unwrap();
    assert_eq!(
        std::fs::read(&direct).unwrap(),
        std::fs::read(path).unwrap(),
        "{}",
        direct.display()
    );
}

#[test]
fn streamed_and_in_memory_bakes_write_the_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            "gen:studded",
            [40, 24, 9],
            Extent {
                sx: 1.0,
                sy: 0.6,
                sz: 0.05,
            },
        ),
        (
            "gen:noise",
            [33, 17, 16],
            Extent {
                sx: 1.0,
                sy: 1.0,
                sz: 0.1,
            },
        ),
        // Coarse and shallow: values far below the surface.
        (
            "gen:gaussian",
            [8, 8, 4],
            Extent {
                sx: 1.0,
                sy: 1.0,
                sz: 0.4,
            },
        ),
    ];
    for (spec, size, extent) in cases {
        for address in [Address::Clamp, Address::Repeat] {
            let height = generate(spec, 48, 40, address).unwrap();
            let opts = BakeOptions {
                size,
                extent,
                ..Default::default()
            };
            let map = bake(&height, &opts).unwrap();
            for (ext, formats) in [
                ("ktx2", &[Format::R8, Format::R16F, Format::R32F][..]),
                ("dds", &[Format::R8, Format::R16F, Format::R32F][..]),
                ("npy", &[Format::R32F][..]),
            ] {
                for &format in formats {
                    let want = dir.path().join(format!("want.{ext}"));
                    write_distance_map(&want, &map.distance, extent, format).unwrap();
                    let want = std::fs::read(&want).unwrap();
                    for slab in [1, 2, 5, size[2]] {
                        let got = dir.path().join(format!("got.{ext}"));
                        streamed(&height, &opts, &got, format, slab);
                        assert!(
                            std::fs::read(&got).unwrap() == want,
                            "{spec} {size:?} {address:?} .{ext} {} slab {slab}: bytes differ",
                            format.name()
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn an_unfinished_or_failed_stream_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let height = generate("gen:studded", 32, 32, Address::Clamp).unwrap();
    let opts = BakeOptions {
        size: [16, 16, 8],
        ..Default::default()
    };
    let path = dir.path().join("m.ktx2");
    {
        // A sink that fails at its second slab, as a write error or an
        // interruption would: the stream is dropped unfinished.
        struct FailingAt2(MapStream, usize);
        impl SlabSink for FailingAt2 {
            fn begin(&mut self, l: BakeLayout) -> displace_core::Result<()> {
                self.0.begin(l)
            }
            fn push(&mut self, s: Slab<'_>) -> displace_core::Result<()> {
                self.1 += 1;
                if self.1 == 2 {
                    return Err(displace_core::Error::Cancelled);
                }
                self.0.push(s)
            }
        }
        let stream = MapStream::create(&path, Format::R8, opts.size, opts.extent).unwrap();
        let r = bake_streamed(&height, &opts, 2, &mut FailingAt2(stream, 0));
        assert!(matches!(r, Err(displace_core::Error::Cancelled)));
    }
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "{left:?}");
    // A missing directory fails when the stream is created, before any work.
    let missing = dir.path().join("no/such/dir/m.ktx2");
    let err = MapStream::create(&missing, Format::R8, opts.size, opts.extent)
        .err()
        .unwrap();
    assert!(err.to_string().contains("no/such/dir"), "{err}");
}

/// A stream that counts the slabs of codes it takes and fails at the
/// `fail_at`-th (never, for 0), as a write error would.
struct Coded {
    stream: MapStream,
    pushed: usize,
    fail_at: usize,
}

impl SlabSink for Coded {
    fn begin(&mut self, l: BakeLayout) -> displace_core::Result<()> {
        self.stream.begin(l)
    }
    fn push(&mut self, s: Slab<'_>) -> displace_core::Result<()> {
        self.stream.push(s)
    }
    fn encoder(&self) -> Option<displace_core::distance_map::R8Encoder> {
        self.stream.encoder()
    }
    fn code_buffer(&mut self) -> Vec<u8> {
        self.stream.code_buffer()
    }
    fn push_codes(&mut self, s: CodedSlab) -> displace_core::Result<()> {
        self.pushed += 1;
        if self.pushed == self.fail_at {
            return Err(displace_core::Error::Cancelled);
        }
        self.stream.push_codes(s)
    }
}

/// A pool of `threads` worker threads, whatever the machine's cores.
fn thread_pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
}

#[test]
fn r8_codes_reach_the_file_in_order_from_many_threads() {
    // More threads than cores, so that slices finish out of order and wait
    // their turn; KTX2 settles its range after the first slab, DDS knows it
    // from the start.
    let dir = tempfile::tempdir().unwrap();
    let pool = thread_pool(5);
    for (spec, size) in [("gen:studded", [37, 29, 23]), ("gen:noise", [64, 48, 17])] {
        let height = generate(spec, 50, 44, Address::Clamp).unwrap();
        let extent = Extent::new(1.0, 0.8, 0.06).unwrap();
        let opts = BakeOptions::new(size, extent);
        let map = bake(&height, &opts).unwrap();
        for ext in ["ktx2", "dds"] {
            let want = dir.path().join(format!("want.{ext}"));
            write_distance_map(&want, &map.distance, extent, Format::R8).unwrap();
            for slab in [1, 3, 5] {
                let got = dir.path().join(format!("got.{ext}"));
                let stream = MapStream::create(&got, Format::R8, size, extent).unwrap();
                let mut sink = Coded {
                    stream,
                    pushed: 0,
                    fail_at: 0,
                };
                pool.install(|| bake_streamed(&height, &opts, slab, &mut sink))
                    .unwrap();
                // All but the slices before the range settled came as codes.
                let first_slab = if ext == "ktx2" { slab } else { 0 };
                assert_eq!(
                    sink.pushed,
                    size[2] - first_slab,
                    "{spec} .{ext} slab {slab}"
                );
                sink.stream.finish().unwrap();
                assert!(
                    std::fs::read(&got).unwrap() == std::fs::read(&want).unwrap(),
                    "{spec} .{ext} slab {slab}: bytes differ"
                );
            }
        }
    }
}

#[test]
fn a_coded_bake_that_fails_or_is_interrupted_stops_and_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let pool = thread_pool(3);
    let height = generate("gen:studded", 32, 32, Address::Clamp).unwrap();
    let size = [24, 24, 40];
    let path = dir.path().join("m.ktx2");
    // The sink fails at its fifth slab of codes: the error comes back, the
    // threads stop (the call returns), and the file is gone.
    {
        let opts = BakeOptions::new(size, Extent::new(1.0, 1.0, 0.05).unwrap());
        let stream = MapStream::create(&path, Format::R8, size, opts.extent).unwrap();
        let mut sink = Coded {
            stream,
            pushed: 0,
            fail_at: 5,
        };
        let r = pool.install(|| bake_streamed(&height, &opts, 3, &mut sink));
        assert!(matches!(r, Err(displace_core::Error::Cancelled)), "{r:?}");
        assert_eq!(sink.pushed, 5);
    }
    // Cancelled from the progress callback after a dozen slices.
    {
        let cancel = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = cancel.clone();
        let opts = BakeOptions {
            size,
            extent: Extent::new(1.0, 1.0, 0.05).unwrap(),
            progress: Some(std::sync::Arc::new(move |done, _| {
                if done >= 12 {
                    flag.store(true, std::sync::atomic::Ordering::Relaxed);
                }
            })),
            cancel: Some(cancel),
        };
        let mut stream = MapStream::create(&path, Format::R8, size, opts.extent).unwrap();
        let r = pool.install(|| bake_streamed(&height, &opts, 3, &mut stream));
        assert!(matches!(r, Err(displace_core::Error::Cancelled)), "{r:?}");
    }
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "{left:?}");
}
