//! The multigrid's parallel loops, all through the crate's one compiled rayon loop ([`run`]):
//! a pass hands it one task per chunk of entries (or per plane), and the loop over the chunk's
//! rows stays the pass's own, generic code. Rayon's plumbing is then compiled once for the multigrid
//! instead of once per pass, band count, precision and row codec; the call through a trait
//! object happens once per chunk, not per row.

use crate::par::run;
use std::sync::{Mutex, PoisonError};

/// A task's item, then its result.
enum Slot<T, R> {
    Item(T),
    Running,
    Done(R),
}

/// `f(i, item)` for each of `items` in parallel; the results in the items' order.
///
/// Plain loops, not iterator chains: this is compiled once per pass, so it is kept small.
pub(super) fn map_each<T: Send, R: Send>(items: Vec<T>, f: impl Fn(usize, T) -> R + Sync) -> Vec<R> {
    // One slot per task, each locked by its task alone: the lock only proves to the compiler
    // that the tasks' items and results are disjoint.
    let mut slots = Vec::with_capacity(items.len());
    for item in items {
        slots.push(Mutex::new(Slot::Item(item)));
    }
    run(slots.len(), &|i| {
        let mut slot = slots[i].lock().unwrap_or_else(PoisonError::into_inner);
        if let Slot::Item(item) = std::mem::replace(&mut *slot, Slot::Running) {
            *slot = Slot::Done(f(i, item));
        }
    });
    let mut results = Vec::with_capacity(slots.len());
    for slot in slots {
        // Rayon runs every task once (a task's panic is raised by `run`): each slot is done.
        if let Slot::Done(r) = slot.into_inner().unwrap_or_else(PoisonError::into_inner) {
            results.push(r);
        }
    }
    results
}

/// [`map_each`] over the `size`-entry chunks of `v` (the last may be shorter).
pub(super) fn map_chunks<T: Send, R: Send>(v: &mut [T], size: usize, f: impl Fn(usize, &mut [T]) -> R + Sync) -> Vec<R> {
    let mut chunks = Vec::with_capacity(v.len().div_ceil(size));
    for chunk in v.chunks_mut(size) {
        chunks.push(chunk);
    }
    map_each(chunks, f)
}

/// `f(ci, chunk)` for each `size`-entry chunk of `v` in parallel.
pub(super) fn for_chunks<T: Send>(v: &mut [T], size: usize, f: impl Fn(usize, &mut [T]) + Sync) {
    map_chunks(v, size, f);
}

/// `f(i)` for every i in `0..tasks` in parallel; the results in order.
pub(super) fn map_range<R: Send>(tasks: usize, f: impl Fn(usize) -> R + Sync) -> Vec<R> {
    map_each(vec![(); tasks], |i, ()| f(i))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_cover_the_slice_once_and_results_keep_their_order() {
        let mut v: Vec<usize> = vec![0; 10_007];
        let firsts = map_chunks(&mut v, 1000, |ci, xs| {
            for (t, x) in xs.iter_mut().enumerate() {
                *x += ci * 1000 + t + 1;
            }
            (ci, xs.len())
        });
        assert_eq!(v, (1..=10_007).collect::<Vec<_>>());
        assert_eq!(firsts.len(), 11);
        assert!(firsts.iter().enumerate().all(|(i, (ci, len))| *ci == i && *len == if i == 10 { 7 } else { 1000 }));
        assert_eq!(map_range(5, |i| i * i), [0, 1, 4, 9, 16]);
        assert!(map_range(0, |i| i).is_empty());
    }
}
