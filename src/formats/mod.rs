//! Mesh file formats: reading STL, OBJ, PLY and glTF/GLB into a [`crate::geometry::TriMesh`]
//! and writing GLB, STL, OBJ and PLY.
