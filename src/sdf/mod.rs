//! The neural signed-distance auto-decoder (burn): model, loss, training and inference.
