//! The compute pool (docs/architecture.md §A3): a fixed set of threads, one per core,
//! on which session actors step their monitors, so a heavy session can never stall the
//! async runtime that serves sockets, `/healthz` and every other session.
//!
//! Fairness comes from the queue: it is first in, first out, and an actor has at most
//! one slice of work queued at a time (it awaits each before sending the next). A frame
//! is stepped in slices of at most [`SLICE_BUDGET`] of compute each (checked between
//! epochs), so a session streaming big batches takes turns with the others instead of
//! holding a thread for the whole batch; one epoch is bounded by the dimension limits.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::{Arc, Mutex, mpsc};
use std::time::Duration;

use tokio::sync::oneshot;

/// Compute one actor takes per turn before it queues again behind the others.
pub const SLICE_BUDGET: Duration = Duration::from_millis(2);

type Job = Box<dyn FnOnce() + Send + 'static>;

/// Why a job gave no answer.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ComputeError {
    /// The job panicked (its inputs are lost).
    #[error("a compute job panicked")]
    Panicked,
    /// The pool has stopped.
    #[error("the compute pool has stopped")]
    Stopped,
}

/// The pool. Cheap to share (`Arc`); its threads end when the last handle is dropped.
#[derive(Debug)]
pub struct ComputePool {
    jobs: Mutex<Option<mpsc::Sender<Job>>>,
    threads: usize,
}

impl ComputePool {
    /// A pool of `threads` threads (at least 1).
    pub fn new(threads: usize) -> Arc<Self> {
        let threads = threads.max(1);
        let (tx, rx) = mpsc::channel::<Job>();
        let rx = Arc::new(Mutex::new(rx));
        for i in 0..threads {
            let rx = rx.clone();
            let spawned = std::thread::Builder::new()
                .name(format!("navguard-compute-{i}"))
                .spawn(move || {
                    loop {
                        // The lock is held only to take the next job, never while it runs.
                        let job = match rx.lock() {
                            Ok(rx) => rx.recv(),
                            Err(poisoned) => poisoned.into_inner().recv(),
                        };
                        match job {
                            Ok(job) => job(),
                            Err(_) => break, // every sender dropped: the pool is gone
                        }
                    }
                });
            if let Err(e) = spawned {
                tracing::error!(error = %e, "could not start a compute thread");
            }
        }
        Arc::new(ComputePool {
            jobs: Mutex::new(Some(tx)),
            threads,
        })
    }

    /// A pool with one thread per available core.
    pub fn per_core() -> Arc<Self> {
        ComputePool::new(std::thread::available_parallelism().map_or(2, |n| n.get()))
    }

    /// Threads in the pool.
    pub fn threads(&self) -> usize {
        self.threads
    }

    /// Runs `f` on a pool thread and waits for its answer without blocking the runtime.
    pub async fn run<F, R>(&self, f: F) -> Result<R, ComputeError>
    where
        F: FnOnce() -> R + Send + 'static,
        R: Send + 'static,
    {
        let (tx, rx) = oneshot::channel();
        let job: Job = Box::new(move || {
            let answer = catch_unwind(AssertUnwindSafe(f)).map_err(|_| ComputeError::Panicked);
            let _ = tx.send(answer);
        });
        {
            let jobs = self.jobs.lock().unwrap_or_else(|p| p.into_inner());
            let sender = jobs.as_ref().ok_or(ComputeError::Stopped)?;
            sender.send(job).map_err(|_| ComputeError::Stopped)?;
        }
        rx.await.map_err(|_| ComputeError::Stopped)?
    }

    /// Stops taking jobs; threads end once the queued jobs are done.
    pub fn stop(&self) {
        self.jobs.lock().unwrap_or_else(|p| p.into_inner()).take();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test(flavor = "current_thread")]
    async fn jobs_run_off_the_runtime_and_answer() {
        let pool = ComputePool::new(2);
        let caller = std::thread::current().id();
        let (v, id) = pool
            .run(|| (21 * 2, std::thread::current().id()))
            .await
            .unwrap();
        assert_eq!(v, 42);
        assert_ne!(id, caller, "ran on a pool thread");
        assert_eq!(pool.threads(), 2);
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_panicking_job_is_an_error_and_the_pool_goes_on() {
        let pool = ComputePool::new(1);
        let r: Result<(), _> = pool.run(|| panic!("boom")).await;
        assert_eq!(r, Err(ComputeError::Panicked));
        assert_eq!(pool.run(|| 7).await, Ok(7));
        pool.stop();
        assert_eq!(pool.run(|| 8).await, Err(ComputeError::Stopped));
    }

    #[tokio::test(flavor = "current_thread")]
    async fn a_busy_pool_leaves_the_runtime_free() {
        // The job blocks its pool thread until a task on the (single-threaded) runtime
        // answers: that only happens if running the job left the runtime free.
        let pool = ComputePool::new(1);
        let (tx, rx) = std::sync::mpsc::channel::<u32>();
        let job = pool.run(move || rx.recv_timeout(Duration::from_secs(10)));
        let answer = async move {
            tokio::task::yield_now().await;
            tx.send(7).unwrap();
        };
        let (got, ()) = tokio::join!(job, answer);
        assert_eq!(got.unwrap(), Ok(7));
    }
}
