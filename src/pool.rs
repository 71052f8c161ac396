//! Where the native work runs: on a worker of rayon's global pool.
//!
//! A parallel loop started from a thread outside the pool (the caller's: `main`, a
//! Python thread, a benchmark) hands its jobs to the workers and puts the calling
//! thread to sleep until they finish, so every loop costs two context switches on top
//! of the workers' own wake-ups. One hard-EM frame runs some hundred such loops (the
//! unary terms, each LM cost and normal system, the free-space term), and on a 2-core
//! machine those switches cost more than a fifth of the frame (docs/design.md). Started
//! on a worker, the same loops split their work with the other
//! worker directly; the caller sleeps once for the whole call.

/// Runs `op` on a worker of rayon's global pool and returns its result: in place when
/// the calling thread is already a worker (of any pool, so a caller's own pool is
/// kept), otherwise by handing it to the pool and waiting once. A panic in `op`
/// reaches the caller as it would have without the hand-over.
pub fn on_worker<R: Send>(op: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_some() {
        op()
    } else {
        rayon::scope(|_| op())
    }
}

#[cfg(test)]
mod tests {
    use super::on_worker;

    #[test]
    fn work_runs_on_a_worker_and_stays_in_a_callers_pool() {
        assert_eq!(rayon::current_thread_index(), None);
        let (inside, value) = on_worker(|| (rayon::current_thread_index(), 6 * 7));
        assert!(inside.is_some(), "not moved onto a worker");
        assert_eq!(value, 42);
        // Already on a worker of another pool: runs there, not in the global pool.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .thread_name(|_| "callers-pool".into())
            .build()
            .unwrap();
        let name = pool.install(|| on_worker(|| std::thread::current().name().map(String::from)));
        assert_eq!(name.as_deref(), Some("callers-pool"));
    }

    #[test]
    fn a_panic_reaches_the_caller() {
        let r = std::panic::catch_unwind(|| on_worker(|| panic!("from the worker")));
        let msg = r.unwrap_err();
        assert_eq!(msg.downcast_ref::<&str>(), Some(&"from the worker"));
    }
}
