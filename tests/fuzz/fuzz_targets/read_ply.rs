//! Arbitrary bytes through the PLY reader: it must return a mesh that validates or an
//! error, never panic, hang or allocate without bound.
#![no_main]

use aortagen::formats::{MeshFormat, read_mesh_bytes};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = read_mesh_bytes(data, MeshFormat::Ply, "fuzz.ply") {
        // What the reader accepts is a valid mesh: a second validation agrees.
        assert!(mesh.validate().is_ok());
    }
});
