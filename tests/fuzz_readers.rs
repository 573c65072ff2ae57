//! Every file reader under seeded fuzzing (issue 14): each format of `rgm_data::io::FORMATS`
//! (PLY, OFF, XYZ, CSV, NPY, PCD, LAS, LAZ) and safetensors weights get thousands of inputs
//! mutated from the valid files of `tests/fuzz_corpus/` (named by the format's extensions) and
//! random bytes, and must answer each with points or an error: no panic, no hang, memory bounded
//! by the input's size. `RGM_FUZZ_INPUTS` sets the number of inputs per reader (10,000 by
//! default; more for a longer hunt).

use std::path::Path;

use rgm_data::io::{checked_cloud, xyz, PointFormat, FORMATS};
use rgm_tests::mutation::{corpus, peak_bytes, CountingAllocator, Fuzz};

#[global_allocator]
static ALLOC: CountingAllocator = CountingAllocator;

fn fuzz() -> Fuzz {
    let inputs = std::env::var("RGM_FUZZ_INPUTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000);
    Fuzz {
        inputs,
        ..Fuzz::default()
    }
}

/// The seeds of `format`: the corpus files named by its extensions.
fn seeds(format: &dyn PointFormat) -> Vec<Vec<u8>> {
    let endings: Vec<String> = format
        .extensions()
        .iter()
        .map(|e| format!(".{e}"))
        .collect();
    corpus(&endings.iter().map(String::as_str).collect::<Vec<_>>())
}

/// The points `format` reads from `bytes` (warnings dropped), checked as `read_point_cloud`
/// checks them.
fn read_points(format: &dyn PointFormat, bytes: &[u8]) {
    let path = Path::new("f");
    if let Ok(points) = format.parse(bytes, path, &mut Vec::new()) {
        let _ = checked_cloud(points, path);
    }
}

#[test]
fn every_format_survives_fuzzing() {
    for &format in FORMATS {
        let seeds = seeds(format);
        // Each seed reads back (mutations start from valid files); what the largest reading
        // takes (LAZ's decoder holds about 2 MB of models whatever the file) is allowed besides
        // the bound per input byte.
        let mut fixed = 0;
        for seed in &seeds {
            let (peak, points) =
                peak_bytes(|| format.parse(seed, Path::new("seed"), &mut Vec::new()));
            assert!(points.is_ok_and(|p| !p.is_empty()), "{}", format.name());
            fixed = fixed.max(peak);
        }
        let fuzz = Fuzz {
            slack: fuzz().slack + fixed,
            ..fuzz()
        };
        fuzz.run(format.name(), &seeds, |b| read_points(format, b));
    }
}

#[test]
fn the_corpus_holds_each_encoding() {
    let count = |name: &str| {
        let format = FORMATS.iter().find(|f| f.name() == name).unwrap();
        seeds(*format).len()
    };
    // PLY: ascii, binary little- and big-endian; PCD: ascii, binary, binary_compressed.
    assert_eq!([count("PLY"), count("PCD"), count("LAZ")], [3, 3, 1]);
    // The seeds with a byte-order mark read every point (a spreadsheet's "CSV UTF-8").
    let first = |name: &str| {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("fuzz_corpus")
            .join(name);
        xyz::parse(&std::fs::read(&path).unwrap(), &path).unwrap()[0]
    };
    assert_eq!(first("bom.csv"), rgm_geom::Point3::new(0.5, -1.0, 2.0));
    assert_eq!(first("bom.xyz"), rgm_geom::Point3::new(1.0, 2.0, 3.0));
}

#[test]
fn safetensors_reader_survives_fuzzing() {
    let seeds = corpus(&[".safetensors"]);
    // The seed holds F32 and BF16 tensors and reads back.
    let (tensors, _) =
        rgm_nn::io::read_tensors_from_bytes::<f32>(&seeds[0], Path::new("seed")).unwrap();
    assert_eq!(
        tensors["m.weight"].as_slice().unwrap(),
        &[1.0, -2.5, f32::from_bits(0x3DCD_0000)]
    );
    fuzz().run("safetensors", &seeds, |b| {
        let _ = rgm_nn::io::read_tensors_from_bytes::<f32>(b, Path::new("f.safetensors"));
    });
}

/// The bound holds something: a reader that allocated from a count in the file, unchecked,
/// would fail it.
#[test]
fn the_memory_bound_catches_an_allocation_from_a_count() {
    let tiny = Fuzz {
        inputs: 1,
        ..Fuzz::default()
    };
    let caught = std::panic::catch_unwind(|| {
        tiny.run("greedy", &[b"ply".to_vec()], |b| {
            let _: Vec<u8> = Vec::with_capacity(4096 * b.len() + (2 << 20));
        })
    });
    assert!(caught.is_err());
}

/// Issue 27, case 7: a 40 GB sparse `.ply` aborted rgm (an allocation of its size). A sparse
/// file larger than any memory, of every format, is refused from its size, before a byte is
/// read or allocated.
#[test]
fn sparse_files_larger_than_memory_are_refused_from_their_size() {
    let dir = rgm_tests::Scratch::new("fuzz-sparse");
    for format in FORMATS {
        let path = dir.join(format!("huge.{}", format.extensions()[0]));
        let mut file = std::fs::File::create(&path).unwrap();
        if let Some(magic) = format.magic() {
            // A file whose magic string is right, so that its size is what refuses it.
            std::io::Write::write_all(&mut file, magic).unwrap();
        }
        file.set_len(1 << 42).unwrap(); // 4.4 TB, holding nothing
        let (peak, read) = peak_bytes(|| rgm_data::read_point_cloud(&path));
        let err = read.unwrap_err().to_string();
        assert!(peak < 1 << 20, "{peak} bytes");
        // A text file is sized by what its points may take (5 times its bytes).
        let sized = if format.is_text() {
            " of text, whose points may take 21990.2 GB,"
        } else {
            ","
        };
        assert!(
            err.starts_with(&format!(
                "{}: 4398.0 GB{sized} more than the ",
                path.display()
            )),
            "{err}"
        );
    }
}

/// Issue 27, case 7: a garbage `.npy` was read whole before its magic string was checked. Its
/// first bytes are read first: a sparse 4.4 TB file of zeros is refused for its magic string,
/// reading nothing else.
#[test]
fn a_garbage_npy_is_refused_for_its_magic_string_unread() {
    let dir = rgm_tests::Scratch::new("fuzz-garbage-npy");
    let path = dir.join("garbage.npy");
    std::fs::File::create(&path)
        .unwrap()
        .set_len(1 << 42)
        .unwrap();
    let (peak, read) = peak_bytes(|| rgm_data::read_point_cloud(&path));
    let err = read.unwrap_err().to_string();
    assert!(peak < 1 << 20, "{peak} bytes");
    assert!(err.contains("missing the magic string"), "{err}");
}

/// FIFOs, folders and devices are refused without being opened (a FIFO would block).
#[test]
fn fifos_and_devices_are_refused_unopened() {
    let dir = rgm_tests::Scratch::new("fuzz-fifo");
    let fifo = dir.join("pipe.ply");
    assert!(std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let (zero, folder) = (dir.join("zero.ply"), dir.join("folder.ply"));
    std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
    std::fs::create_dir(&folder).unwrap();
    for path in [&fifo, &zero, &folder] {
        let err = rgm_data::read_point_cloud(path).unwrap_err().to_string();
        assert!(err.contains(", not a file"), "{err}");
    }
}
