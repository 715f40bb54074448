//! How ranks talk: one small trait, implemented by a single process, by in-process ranks on
//! threads (tests, and checking a decomposition without MPI), and by MPI (feature `mpi`).
//!
//! The engine needs only one collective, [`Comm::exchange`] (every rank sends one buffer to every
//! rank, possibly empty); sums, maxima and agreement are built on it. Reductions add the ranks'
//! contributions in rank order, so every rank gets the same bits.

use std::sync::{Arc, Barrier, Mutex};

/// A group of ranks running the same program.
pub trait Comm {
    /// This rank, `0 .. size()`.
    fn rank(&self) -> usize;
    /// Number of ranks.
    fn size(&self) -> usize;
    /// All-to-all: `send[s]` goes to rank `s`; returns what each rank sent to this one, by source.
    /// Every rank must call it the same number of times (a collective).
    fn exchange(&self, send: Vec<Vec<u64>>) -> Vec<Vec<u64>>;

    /// Element-wise sums over all ranks, added in rank order (the same bits on every rank).
    fn sum(&self, x: &[f64]) -> Vec<f64> {
        self.reduce(x, 0.0, |a, b| a + b)
    }

    /// Element-wise wrapping integer sums over all ranks (exact, in any order).
    fn sum_counts(&self, x: &[u64]) -> Vec<u64> {
        let got = self.exchange(vec![x.to_vec(); self.size()]);
        let mut out = vec![0u64; x.len()];
        for part in &got {
            for (o, c) in out.iter_mut().zip(part) {
                *o = o.wrapping_add(*c);
            }
        }
        out
    }

    /// Element-wise maxima over all ranks.
    fn max(&self, x: &[f64]) -> Vec<f64> {
        self.reduce(x, f64::NEG_INFINITY, f64::max)
    }

    /// Element-wise `op` over all ranks' `x`, folded from `init` in rank order.
    fn reduce(&self, x: &[f64], init: f64, op: fn(f64, f64) -> f64) -> Vec<f64> {
        let bits: Vec<u64> = x.iter().map(|v| v.to_bits()).collect();
        let got = self.exchange(vec![bits; self.size()]);
        let mut out = vec![init; x.len()];
        for part in &got {
            for (o, b) in out.iter_mut().zip(part) {
                *o = op(*o, f64::from_bits(*b));
            }
        }
        out
    }

    /// Whether every rank passed `true` (also a barrier): how ranks agree to go on or stop.
    fn all(&self, ok: bool) -> bool {
        let got = self.exchange(vec![vec![ok as u64]; self.size()]);
        got.iter().all(|m| m.first() == Some(&1))
    }
}

/// One process: rank 0 of 1.
pub struct Single;

impl Comm for Single {
    fn rank(&self) -> usize {
        0
    }
    fn size(&self) -> usize {
        1
    }
    fn exchange(&self, send: Vec<Vec<u64>>) -> Vec<Vec<u64>> {
        send
    }
}

/// Ranks as threads of one process, exchanging through shared mailboxes. Behaves as MPI ranks do
/// for the engine (each owns its own arrays; only `exchange` moves data), so tests can run any
/// number of ranks without an MPI installation.
pub struct Local {
    rank: usize,
    shared: Arc<Mailboxes>,
}

struct Mailboxes {
    size: usize,
    barrier: Barrier,
    /// `slots[to][from]`.
    slots: Mutex<Vec<Vec<Vec<u64>>>>,
}

impl Local {
    /// `size` connected ranks; hand one to each thread.
    pub fn group(size: usize) -> Vec<Local> {
        let shared = Arc::new(Mailboxes {
            size,
            barrier: Barrier::new(size),
            slots: Mutex::new(vec![vec![Vec::new(); size]; size]),
        });
        (0..size)
            .map(|rank| Local {
                rank,
                shared: shared.clone(),
            })
            .collect()
    }
}

impl Comm for Local {
    fn rank(&self) -> usize {
        self.rank
    }
    fn size(&self) -> usize {
        self.shared.size
    }
    fn exchange(&self, send: Vec<Vec<u64>>) -> Vec<Vec<u64>> {
        assert_eq!(send.len(), self.size(), "one buffer per rank");
        {
            let mut slots = self.shared.slots.lock().unwrap_or_else(|e| e.into_inner());
            for (to, buf) in send.into_iter().enumerate() {
                slots[to][self.rank] = buf;
            }
        }
        self.shared.barrier.wait();
        let got = {
            let mut slots = self.shared.slots.lock().unwrap_or_else(|e| e.into_inner());
            std::mem::replace(&mut slots[self.rank], vec![Vec::new(); self.size()])
        };
        // Nobody may deposit the next round's messages before everyone has collected this one's.
        self.shared.barrier.wait();
        got
    }
}

#[cfg(feature = "mpi")]
pub use self::mpi_comm::Mpi;

#[cfg(feature = "mpi")]
mod mpi_comm {
    use mpi::datatype::{Partition, PartitionMut};
    use mpi::traits::*;

    use super::Comm;

    /// MPI's world communicator.
    pub struct Mpi {
        pub(crate) world: mpi::topology::SimpleCommunicator,
    }

    impl Comm for Mpi {
        fn rank(&self) -> usize {
            self.world.rank() as usize
        }
        fn size(&self) -> usize {
            self.world.size() as usize
        }
        fn exchange(&self, send: Vec<Vec<u64>>) -> Vec<Vec<u64>> {
            let size = self.size();
            assert_eq!(send.len(), size, "one buffer per rank");
            // Counts first, then the data in one MPI_Alltoallv. Messages are halo values of one
            // colour phase, far below MPI's 2^31-element count limit for any patch size.
            let counts: Vec<u64> = send.iter().map(|b| b.len() as u64).collect();
            let mut recv_counts = vec![0u64; size];
            self.world
                .all_to_all_into(&counts[..], &mut recv_counts[..]);
            let to_count =
                |c: &u64| mpi::Count::try_from(*c).expect("halo message exceeds MPI's count limit");
            let sc: Vec<mpi::Count> = counts.iter().map(to_count).collect();
            let rc: Vec<mpi::Count> = recv_counts.iter().map(to_count).collect();
            let displs = |c: &[mpi::Count]| -> Vec<mpi::Count> {
                c.iter()
                    .scan(0, |acc, &x| {
                        let d = *acc;
                        *acc += x;
                        Some(d)
                    })
                    .collect()
            };
            let (sd, rd) = (displs(&sc), displs(&rc));
            let flat: Vec<u64> = send.concat();
            let mut recv = vec![0u64; recv_counts.iter().sum::<u64>() as usize];
            {
                let part = Partition::new(&flat[..], &sc[..], &sd[..]);
                let mut part_mut = PartitionMut::new(&mut recv[..], &rc[..], &rd[..]);
                self.world.all_to_all_varcount_into(&part, &mut part_mut);
            }
            let mut out = Vec::with_capacity(size);
            let mut at = 0usize;
            for &c in &recv_counts {
                out.push(recv[at..at + c as usize].to_vec());
                at += c as usize;
            }
            out
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn local_ranks_exchange_sum_and_agree() {
        let ranks = Local::group(3);
        let results: Vec<_> = std::thread::scope(|s| {
            let handles: Vec<_> = ranks
                .iter()
                .map(|c| {
                    s.spawn(move || {
                        let r = c.rank() as u64;
                        let got = c.exchange((0..3).map(|to| vec![10 * r + to]).collect());
                        let again = c.exchange((0..3).map(|_| vec![r; r as usize]).collect());
                        let sum = c.sum(&[r as f64, 1.0]);
                        let counts = c.sum_counts(&[r, u64::MAX]);
                        let max = c.max(&[r as f64]);
                        let all = c.all(r != 1);
                        (got, again, sum, max, all, counts)
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        for (r, (got, again, sum, max, all, counts)) in results.into_iter().enumerate() {
            assert_eq!(counts, vec![3, u64::MAX - 2]);
            let r = r as u64;
            assert_eq!(got, vec![vec![r], vec![10 + r], vec![20 + r]]);
            assert_eq!(again, vec![vec![], vec![1], vec![2, 2]]);
            assert_eq!(sum, vec![3.0, 3.0]);
            assert_eq!(max, vec![2.0]);
            assert!(!all);
        }
        assert_eq!(Single.exchange(vec![vec![7]]), vec![vec![7]]);
        assert!(Single.all(true));
    }
}
