//! Parallel loops through one compiled rayon loop ([`run`]): a caller hands it one task per
//! chunk of items (or per row, plane, group) as a trait object, and the loop over a chunk's items
//! stays the caller's own code. Rayon's plumbing (producers, consumers, the join tree) is then
//! compiled once instead of once per caller's closure; the call through the trait object
//! happens once per task, not per item, and each helper is compiled once per item and result
//! type, not once per closure.

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

/// A task's item, then its result.
enum Slot<T, R> {
    Item(T),
    Running,
    Done(R),
}

/// `f(i, item)` for each of `items` in parallel, one task per item; the results in the items'
/// order.
pub(crate) fn map_each<T: Send, R: Send>(items: Vec<T>, f: &(dyn Fn(usize, T) -> R + Sync)) -> Vec<R> {
    // One lock per slot, taken by its task alone: it only proves to the compiler that the tasks'
    // items and results are disjoint.
    let slots: Vec<Mutex<Slot<T, R>>> = items.into_iter().map(|item| Mutex::new(Slot::Item(item))).collect();
    run(slots.len(), &|i| {
        let mut slot = slots[i].lock().unwrap_or_else(PoisonError::into_inner);
        if let Slot::Item(item) = std::mem::replace(&mut *slot, Slot::Running) {
            *slot = Slot::Done(f(i, item));
        }
    });
    // Rayon runs every task once (a task's panic is raised by `run`): each slot is done.
    slots
        .into_iter()
        .filter_map(|slot| match slot.into_inner().unwrap_or_else(PoisonError::into_inner) {
            Slot::Done(r) => Some(r),
            _ => None,
        })
        .collect()
}

/// `f(ci, chunk)` for each `size`-item chunk of `v` (the last may be shorter), in parallel; the
/// results in the chunks' order.
pub(crate) fn map_chunks<T: Send, R: Send>(v: &mut [T], size: usize, f: &(dyn Fn(usize, &mut [T]) -> R + Sync)) -> Vec<R> {
    map_each(v.chunks_mut(size.max(1)).collect(), f)
}

/// `f(ci, chunk)` for each `size`-item chunk of `v` (the last may be shorter), in parallel.
pub(crate) fn for_chunks<T: Send>(v: &mut [T], size: usize, f: &(dyn Fn(usize, &mut [T]) + Sync)) {
    // One lock per chunk, taken by its task alone (as in `map_each`).
    let chunks: Vec<Mutex<&mut [T]>> = v.chunks_mut(size.max(1)).map(Mutex::new).collect();
    run(chunks.len(), &|ci| {
        f(ci, &mut chunks[ci].lock().unwrap_or_else(PoisonError::into_inner))
    });
}

/// `f(i)` for every i in `0..tasks` in parallel, one task each; the results in order.
pub(crate) fn map_range<R: Send>(tasks: usize, f: &(dyn Fn(usize) -> R + Sync)) -> Vec<R> {
    map_each(vec![(); tasks], &|i, ()| f(i))
}

/// `f(i)` for every i in `0..n` in parallel, `size` items per task; the results in order.
pub(crate) fn map_items<R: Send + Default + Clone>(n: usize, size: usize, f: &(dyn Fn(usize) -> R + Sync)) -> Vec<R> {
    let mut out = vec![R::default(); n];
    let size = size.max(1);
    for_chunks(&mut out, size, &|ci, xs| {
        for (k, x) in xs.iter_mut().enumerate() {
            *x = f(ci * size + k);
        }
    });
    out
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
        let firsts = map_chunks(&mut v, 1000, &|ci, xs| {
            for x in xs.iter_mut() {
                *x -= 1;
            }
            (ci, xs.len())
        });
        assert_eq!(v, (0..10_007).collect::<Vec<_>>());
        assert_eq!(firsts.len(), 11);
        assert!(firsts
            .iter()
            .enumerate()
            .all(|(i, (ci, len))| *ci == i && *len == if i == 10 { 7 } else { 1000 }));
        assert_eq!(map_each(vec!['a', 'b', 'c'], &|i, c| format!("{i}{c}")), ["0a", "1b", "2c"]);
        assert_eq!(map_range(5, &|i| i * i), [0, 1, 4, 9, 16]);
        assert!(map_range(0, &|i| i).is_empty());
        assert_eq!(map_items(10_007, 1000, &|i| i + 1), (1..=10_007).collect::<Vec<_>>());
        assert!(map_items(0, 0, &|i| i).is_empty());
        let mut none: Vec<u8> = Vec::new();
        for_chunks(&mut none, 0, &|_, _| panic!("no chunk of an empty slice"));
    }
}
