//! The one way a stage drains a queue in parallel.
//!
//! A stage splits its work into chunks (of at most [`CHUNK`] items), runs
//! its kernel on the chunks in parallel, each chunk writing into its own
//! reusable buffer, and then joins the buffers in chunk order. Which
//! thread ran which chunk never shows in the joined output, so queue
//! contents, and therefore images, do not depend on the number of threads.

use std::ops::Range;

use rayon::prelude::*;

use crate::integrators::wavefront::CHUNK;

/// Runs `kernel(c, buffer)` for every chunk `c` in `0..chunks`, in
/// parallel, each chunk with its own buffer from `buffers`; returns the
/// buffers used, in chunk order, for the caller to join in that order.
///
/// `buffers` grows when a call needs more chunks than it has and keeps its
/// buffers between calls, so a stage allocates nothing once they have
/// grown. A buffer still holds what its last chunk left there: `kernel`
/// clears what it fills.
pub fn drain_chunks<B, K>(chunks: usize, buffers: &mut Vec<B>, kernel: K) -> &mut [B]
where
    B: Default + Send,
    K: Fn(usize, &mut B) + Sync,
{
    if buffers.len() < chunks {
        buffers.resize_with(chunks, B::default);
    }
    let used = &mut buffers[..chunks];
    used.par_iter_mut()
        .enumerate()
        .with_max_len(1)
        .for_each(|(c, buffer)| kernel(c, buffer));
    used
}

/// [`drain_chunks`] over the items `0..len` of a queue, [`CHUNK`] items
/// per chunk: `kernel` gets each chunk's item range.
pub fn drain_queue<B, K>(len: usize, buffers: &mut Vec<B>, kernel: K) -> &mut [B]
where
    B: Default + Send,
    K: Fn(Range<usize>, &mut B) + Sync,
{
    drain_chunks(len.div_ceil(CHUNK), buffers, |c, buffer| {
        kernel(chunk_range(c, len), buffer)
    })
}

/// The items of chunk `c` of a queue of `len` items.
fn chunk_range(c: usize, len: usize) -> Range<usize> {
    c * CHUNK..((c + 1) * CHUNK).min(len)
}

/// The item ranges of the chunks of a queue of `len` items, in order: the
/// ranges [`drain_queue`] hands out, for stages whose work items are built
/// from several queues.
pub fn chunk_ranges(len: usize) -> impl Iterator<Item = Range<usize>> {
    (0..len.div_ceil(CHUNK)).map(move |c| chunk_range(c, len))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Squares of `0..len` drained in chunks, joined in chunk order.
    fn squares(len: usize, buffers: &mut Vec<Vec<u64>>) -> Vec<u64> {
        let chunks = drain_queue(len, buffers, |range, out| {
            out.clear();
            out.extend(range.map(|i| (i * i) as u64));
        });
        chunks.iter().flatten().copied().collect()
    }

    #[test]
    fn chunks_cover_the_queue_in_order_whatever_the_thread_count() {
        let len = 5 * CHUNK + 17;
        let expected: Vec<u64> = (0..len).map(|i| (i * i) as u64).collect();
        for threads in [1, 2, 7] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut buffers = Vec::new();
            assert_eq!(pool.install(|| squares(len, &mut buffers)), expected);
            // Buffers are reused, and a shorter queue uses fewer of them.
            assert_eq!(buffers.len(), 6);
            assert_eq!(pool.install(|| squares(10, &mut buffers)), &expected[..10]);
            assert_eq!(buffers.len(), 6);
        }
        let ranges: Vec<_> = chunk_ranges(2 * CHUNK + 1).collect();
        assert_eq!(
            ranges,
            [0..CHUNK, CHUNK..2 * CHUNK, 2 * CHUNK..2 * CHUNK + 1]
        );
        assert_eq!(chunk_ranges(0).count(), 0);
    }
}
