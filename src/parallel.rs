//! Data parallelism for the CPU backend: rayon with the `cpu` feature, plain iterators without it.
//!
//! Every parallel loop in the crate writes disjoint outputs or collects in input order, so both give
//! the same results; only the speed differs. Without `cpu` the stand-ins below give the few rayon
//! methods the crate uses to ordinary iterators, so the loops read the same either way.

#[cfg(feature = "cpu")]
pub(crate) use rayon::prelude::*;

#[cfg(not(feature = "cpu"))]
pub(crate) use sequential::*;

/// How many threads a CPU call uses.
pub(crate) fn threads() -> usize {
    #[cfg(feature = "cpu")]
    return rayon::current_num_threads();
    #[cfg(not(feature = "cpu"))]
    1
}

#[cfg(not(feature = "cpu"))]
mod sequential {
    use std::ops::Range;
    use std::slice::{Chunks, ChunksExactMut, ChunksMut, Iter, IterMut};

    pub(crate) trait ParallelSlice<T> {
        fn par_iter(&self) -> Iter<'_, T>;
        fn par_chunks(&self, size: usize) -> Chunks<'_, T>;
    }

    impl<T> ParallelSlice<T> for [T] {
        fn par_iter(&self) -> Iter<'_, T> {
            self.iter()
        }
        fn par_chunks(&self, size: usize) -> Chunks<'_, T> {
            self.chunks(size)
        }
    }

    pub(crate) trait ParallelSliceMut<T> {
        fn par_iter_mut(&mut self) -> IterMut<'_, T>;
        fn par_chunks_mut(&mut self, size: usize) -> ChunksMut<'_, T>;
        // Used by the CUDA backend's upload (`cuda` without `cpu`).
        #[allow(dead_code)]
        fn par_chunks_exact_mut(&mut self, size: usize) -> ChunksExactMut<'_, T>;
    }

    impl<T> ParallelSliceMut<T> for [T] {
        fn par_iter_mut(&mut self) -> IterMut<'_, T> {
            self.iter_mut()
        }
        fn par_chunks_mut(&mut self, size: usize) -> ChunksMut<'_, T> {
            self.chunks_mut(size)
        }
        fn par_chunks_exact_mut(&mut self, size: usize) -> ChunksExactMut<'_, T> {
            self.chunks_exact_mut(size)
        }
    }

    pub(crate) trait IntoParallelIterator {
        type Iter: Iterator;
        fn into_par_iter(self) -> Self::Iter;
    }

    impl IntoParallelIterator for Range<usize> {
        type Iter = Self;
        fn into_par_iter(self) -> Self {
            self
        }
    }

    // Used by the CUDA backend's image streams (`cuda` without `cpu`).
    impl<T> IntoParallelIterator for Vec<T> {
        type Iter = std::vec::IntoIter<T>;
        fn into_par_iter(self) -> Self::Iter {
            self.into_iter()
        }
    }

    /// rayon's iterator methods that std spells differently.
    pub(crate) trait ParallelIterator: Iterator + Sized {
        fn flat_map_iter<U: IntoIterator, F: FnMut(Self::Item) -> U>(
            self,
            f: F,
        ) -> std::iter::FlatMap<Self, U, F> {
            self.flat_map(f)
        }

        fn for_each_init<S, I: FnMut() -> S, F: FnMut(&mut S, Self::Item)>(
            self,
            mut init: I,
            mut op: F,
        ) {
            let mut state = init();
            self.for_each(|item| op(&mut state, item));
        }

        // Used by the CUDA backend's upload (`cuda` without `cpu`).
        #[allow(dead_code)]
        fn with_min_len(self, _len: usize) -> Self {
            self
        }
    }

    impl<I: Iterator> ParallelIterator for I {}
}
