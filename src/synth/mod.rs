//! The embedded default dataset: parametric aortic-root surfaces in millimetres.
