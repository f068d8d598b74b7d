//! Arbitrary bytes through the glTF/GLB reader (binary container and JSON with data URIs):
//! it must return a mesh that validates or an error, never panic or allocate without bound.
#![no_main]

use aortagen::formats::{MeshFormat, read_mesh_bytes};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    for format in [MeshFormat::Glb, MeshFormat::Gltf] {
        if let Ok(mesh) = read_mesh_bytes(data, format, "fuzz.glb") {
            assert!(mesh.validate().is_ok());
        }
    }
});
