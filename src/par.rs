//! Parallel loops through one compiled rayon loop ([`run`]): a caller hands it one task per
//! chunk of items (or per row, plane, group) as a trait object, and the loop over a chunk's items
//! stays the caller's own code. Rayon's plumbing (producers, consumers, the join tree) is then
//! compiled once instead of once per caller's closure; the call through the trait object
//! happens once per chunk, not per item.

use rayon::prelude::*;
use std::sync::{Mutex, PoisonError};

/// Items per task for loops over voxels or values with no natural unit (rows, planes): enough
/// work per task to hide rayon's per-task cost, enough tasks to balance two to 64 threads on a
/// 200×160×120 grid.
pub(crate) const CHUNK: usize = 4096;

/// `task(i)` for every i in `0..tasks`, on rayon's pool.
pub(crate) fn run(tasks: usize, task: &(dyn Fn(usize) + Sync)) {
    (0..tasks).into_par_iter().for_each(task);
}

/// `f(ci, chunk)` for each `size`-item chunk of `v` (the last may be shorter), in parallel.
pub(crate) fn for_chunks<T: Send>(v: &mut [T], size: usize, f: &(dyn Fn(usize, &mut [T]) + Sync)) {
    // One lock per chunk, taken by its task alone: it only proves to the compiler that the
    // tasks' chunks are disjoint.
    let chunks: Vec<Mutex<&mut [T]>> = v.chunks_mut(size.max(1)).map(Mutex::new).collect();
    run(chunks.len(), &|ci| {
        f(ci, &mut chunks[ci].lock().unwrap_or_else(PoisonError::into_inner))
    });
}

/// `f(i)` for every i in `0..tasks` in parallel; the results in order.
pub(crate) fn map_range<R: Send>(tasks: usize, f: &(dyn Fn(usize) -> R + Sync)) -> Vec<R> {
    let mut slots: Vec<Option<R>> = Vec::with_capacity(tasks);
    slots.resize_with(tasks, || None);
    for_chunks(&mut slots, 1, &|i, slot| slot[0] = Some(f(i)));
    // Rayon runs every task once (a task's panic is raised by `run`): every slot is filled.
    slots.into_iter().flatten().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_cover_the_slice_once_and_results_keep_their_order() {
        let mut v: Vec<usize> = vec![0; 10_007];
        for_chunks(&mut v, 1000, &|ci, xs| {
            for (t, x) in xs.iter_mut().enumerate() {
                *x += ci * 1000 + t + 1;
            }
        });
        assert_eq!(v, (1..=10_007).collect::<Vec<_>>());
        assert_eq!(map_range(5, &|i| i * i), [0, 1, 4, 9, 16]);
        assert!(map_range(0, &|i| i).is_empty());
        let mut none: Vec<u8> = Vec::new();
        for_chunks(&mut none, 0, &|_, _| panic!("no chunk of an empty slice"));
    }
}
