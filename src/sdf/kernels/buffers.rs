//! Host buffers the network passes reuse from one training step to the next.
//!
//! A training step of the widest network saves about a gigabyte for its backward pass and
//! allocates scratch and gradient accumulators per thread. Freshly allocated, every page of
//! them is mapped and cleared by the kernel on first write: about an eighth of a step
//! (`clear_page_erms` under gemm's stores, measured with `perf`). A [`Buffer`] goes back to a
//! small per-type pool when dropped and the next request of at most its capacity takes it
//! again, already mapped. A training run frees what it leaves in the pools when it ends
//! ([`release_free_buffers`], called when an `SdfTrainer` is dropped).

use std::ops::{Deref, DerefMut};
use std::sync::Mutex;

use crate::sdf::kernels::softplus::HostFloat;

/// Buffers kept per pool; beyond this the smallest is freed.
const KEPT: usize = 64;

/// Free buffers of one element type.
#[derive(Debug)]
pub struct Pool<E> {
    free: Mutex<Vec<Vec<E>>>,
}

impl<E> Default for Pool<E> {
    fn default() -> Self {
        Self::new()
    }
}

impl<E> Pool<E> {
    /// An empty pool.
    pub const fn new() -> Self {
        Self {
            free: Mutex::new(Vec::new()),
        }
    }
}

/// A float type with a pool of its own.
pub trait Pooled: HostFloat {
    /// The pool of this type's buffers.
    fn pool() -> &'static Pool<Self>;
}

static POOL_F32: Pool<f32> = Pool::new();
static POOL_F64: Pool<f64> = Pool::new();

impl Pooled for f32 {
    fn pool() -> &'static Pool<Self> {
        &POOL_F32
    }
}

impl Pooled for f64 {
    fn pool() -> &'static Pool<Self> {
        &POOL_F64
    }
}

/// Frees the kept buffers of every element type: what a finished training run leaves behind
/// (its saved values alone can be a gigabyte), so that a long-running process does not hold
/// them until the next run.
pub fn release_free_buffers() {
    f32::pool().release();
    f64::pool().release();
}

/// A vector that returns to its pool when dropped.
#[derive(Debug)]
pub struct Buffer<E: HostFloat + 'static> {
    values: Vec<E>,
    pool: &'static Pool<E>,
}

impl<E: Pooled> Buffer<E> {
    /// `len` values whose contents are unspecified (those of an earlier use): for buffers
    /// the caller overwrites before reading.
    pub fn reused(len: usize) -> Self {
        E::pool().take(len)
    }

    /// `len` zeros.
    pub fn zeroed(len: usize) -> Self {
        let mut b = Self::reused(len);
        b.values.fill(E::ZERO);
        b
    }
}

impl<E: HostFloat> Pool<E> {
    /// A buffer of `len` values from this pool (unspecified contents), or a new one.
    pub fn take(&'static self, len: usize) -> Buffer<E> {
        if len == 0 {
            // Nothing to reuse: a kept buffer stays for a request that needs it.
            return Buffer {
                values: Vec::new(),
                pool: self,
            };
        }
        let recycled = {
            let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
            // The smallest kept buffer that is large enough.
            let best = free
                .iter()
                .enumerate()
                .filter(|(_, v)| v.capacity() >= len)
                .min_by_key(|(_, v)| v.capacity())
                .map(|(i, _)| i);
            best.map(|i| free.swap_remove(i))
        };
        let mut values = recycled.unwrap_or_default();
        values.truncate(len);
        values.resize(len, E::ZERO);
        Buffer { values, pool: self }
    }

    /// Frees every kept buffer (those in use are unaffected and return later).
    pub fn release(&self) {
        self.free.lock().unwrap_or_else(|e| e.into_inner()).clear();
    }

    /// How many free buffers the pool keeps.
    pub fn kept(&self) -> usize {
        self.free.lock().unwrap_or_else(|e| e.into_inner()).len()
    }

    fn give_back(&self, values: Vec<E>) {
        let mut free = self.free.lock().unwrap_or_else(|e| e.into_inner());
        free.push(values);
        if free.len() > KEPT {
            let smallest = free
                .iter()
                .enumerate()
                .min_by_key(|(_, v)| v.capacity())
                .map(|(i, _)| i)
                .expect("pool is not empty");
            free.swap_remove(smallest);
        }
    }
}

impl<E: HostFloat> Deref for Buffer<E> {
    type Target = [E];

    fn deref(&self) -> &[E] {
        &self.values
    }
}

impl<E: HostFloat> DerefMut for Buffer<E> {
    fn deref_mut(&mut self) -> &mut [E] {
        &mut self.values
    }
}

impl<E: HostFloat> Drop for Buffer<E> {
    fn drop(&mut self) {
        let values = std::mem::take(&mut self.values);
        if values.capacity() > 0 {
            self.pool.give_back(values);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_dropped_buffer_is_taken_again_and_never_twice_at_once() {
        static POOL: Pool<f64> = Pool::new();
        let mut a = POOL.take(1000);
        a.iter_mut().for_each(|v| *v = 7.0);
        let ptr = a.as_ptr();
        drop(a);
        let b = POOL.take(900);
        assert_eq!(b.len(), 900);
        assert_eq!(b.as_ptr(), ptr, "the dropped buffer was taken again");
        let c = POOL.take(800);
        assert_eq!(c.len(), 800);
        assert_ne!(c.as_ptr(), ptr, "a buffer in use is never handed out twice");
        let big = POOL.take(5000);
        assert_eq!(big.len(), 5000);
        drop((b, c, big));
        assert_eq!(POOL.kept(), 3);
        let empty = POOL.take(0);
        assert!(empty.is_empty());
        assert_eq!(POOL.kept(), 3, "an empty request leaves the kept buffers");
        POOL.release();
        assert_eq!(POOL.kept(), 0);
    }

    #[test]
    fn zeroed_buffers_are_zero_after_reuse() {
        let mut a = Buffer::<f32>::reused(333);
        a.iter_mut().for_each(|v| *v = 1.5);
        drop(a);
        let b = Buffer::<f32>::zeroed(333);
        assert!(b.iter().all(|&v| v == 0.0));
    }
}
