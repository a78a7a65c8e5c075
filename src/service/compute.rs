//! The compute pool (docs/architecture.md §A3): a fixed set of threads, one per core,
//! on which session actors step their monitors, so a heavy session can never stall the
//! async runtime that serves sockets, `/healthz` and every other session.
//!
//! Fairness comes from the queue: it is first in, first out, and an actor has at most
//! one slice of work queued at a time (it awaits each before sending the next). A frame
//! is stepped in slices of at most [`SLICE_BUDGET`] of compute each (checked between
//! epochs), so a session streaming big batches takes turns with the others instead of
//! holding a thread for the whole batch; one epoch is bounded by the dimension limits.

use std::collections::VecDeque;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
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

/// The jobs waiting for a thread, and whether the pool still takes new ones.
#[derive(Default)]
struct Queue {
    jobs: VecDeque<Job>,
    stopped: bool,
}

/// What the pool's handle and its threads share. Idle threads wait on `ready`, and a new
/// job wakes exactly one of them (`notify_one`). A channel receiver shared behind a mutex
/// would wake two threads per job: the one that takes it and, as that one lets the mutex
/// go, the next in line, only to sleep again in `recv`. Under a virtual machine each
/// wake-up of another core is an interrupt through the hypervisor.
struct Shared {
    queue: Mutex<Queue>,
    ready: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        // A job never runs under the lock, so a poisoned lock still holds a whole queue.
        self.queue.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The next job, waiting while the queue is empty; `None` once the pool has stopped
    /// and its queue is drained.
    fn next(&self) -> Option<Job> {
        let mut queue = self.lock();
        loop {
            if let Some(job) = queue.jobs.pop_front() {
                return Some(job);
            }
            if queue.stopped {
                return None;
            }
            queue = self
                .ready
                .wait(queue)
                .unwrap_or_else(PoisonError::into_inner);
        }
    }
}

/// The pool. Cheap to share (`Arc`); its threads end when the last handle is dropped.
pub struct ComputePool {
    shared: Arc<Shared>,
    threads: usize,
}

impl std::fmt::Debug for ComputePool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ComputePool")
            .field("threads", &self.threads)
            .field("queued", &self.shared.lock().jobs.len())
            .finish()
    }
}

impl ComputePool {
    /// A pool of `threads` threads (at least 1).
    pub fn new(threads: usize) -> Arc<Self> {
        let threads = threads.max(1);
        let shared = Arc::new(Shared {
            queue: Mutex::new(Queue::default()),
            ready: Condvar::new(),
        });
        for i in 0..threads {
            let shared = shared.clone();
            let spawned = std::thread::Builder::new()
                .name(format!("navguard-compute-{i}"))
                .spawn(move || {
                    while let Some(job) = shared.next() {
                        job();
                    }
                });
            if let Err(e) = spawned {
                tracing::error!(error = %e, "could not start a compute thread");
            }
        }
        Arc::new(ComputePool { shared, threads })
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
            let mut queue = self.shared.lock();
            if queue.stopped {
                return Err(ComputeError::Stopped);
            }
            queue.jobs.push_back(job);
        }
        self.shared.ready.notify_one();
        rx.await.map_err(|_| ComputeError::Stopped)?
    }

    /// Stops taking jobs; threads end once the queued jobs are done.
    pub fn stop(&self) {
        self.shared.lock().stopped = true;
        self.shared.ready.notify_all();
    }
}

impl Drop for ComputePool {
    fn drop(&mut self) {
        self.stop();
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
    async fn stopping_runs_the_queued_jobs_and_dropping_ends_the_threads() {
        // One thread, held by the first job until released: the second waits in the queue.
        let pool = ComputePool::new(1);
        let (release, held) = std::sync::mpsc::channel::<()>();
        let first = pool.run(move || held.recv_timeout(Duration::from_secs(10)).is_ok());
        let second = pool.run(|| 2);
        let stop_then_release = async {
            tokio::task::yield_now().await; // both jobs are queued by now
            pool.stop();
            release.send(()).unwrap();
        };
        let (first, second, ()) = tokio::join!(first, second, stop_then_release);
        assert_eq!(first, Ok(true));
        assert_eq!(second, Ok(2), "a job queued before the stop still runs");
        assert_eq!(pool.run(|| 3).await, Err(ComputeError::Stopped));

        // The threads hold the shared queue until they end.
        let pool = ComputePool::new(2);
        assert_eq!(pool.run(|| 4).await, Ok(4));
        let shared = Arc::downgrade(&pool.shared);
        drop(pool);
        for _ in 0..1000 {
            if shared.upgrade().is_none() {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        panic!("the pool's threads did not end after its last handle was dropped");
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
