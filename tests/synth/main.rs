//! Parametric aortic roots, the software renderer and their commands.

mod cli;
mod intersect;
mod params;
mod render;
mod surface;
