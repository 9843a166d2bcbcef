//! Counts of the GPU operations whose per-step cost issue #11 is about, so tests can assert a
//! training step does none of the expensive ones and benchmarks can print them.

use std::sync::atomic::{AtomicU64, Ordering};

/// Running totals since the context was created; `snapshot` differences give per-step counts.
#[derive(Debug, Default)]
pub struct Counters {
    buffers_created: AtomicU64,
    blocking_reads: AtomicU64,
    throttle_waits: AtomicU64,
    submissions: AtomicU64,
    dispatches: AtomicU64,
    bind_groups_created: AtomicU64,
    throttle_wait_ns: AtomicU64,
    submit_ns: AtomicU64,
}

/// A copy of the totals at one moment; subtract two to count what happened in between.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CounterSnapshot {
    /// `create_buffer` calls of the engine (storage, uniform arenas, staging).
    pub buffers_created: u64,
    /// Reads that wait for the GPU to finish the work that produced what they read.
    pub blocking_reads: u64,
    /// Waits for an older step's asynchronous read-back because the CPU ran too far ahead.
    pub throttle_waits: u64,
    pub submissions: u64,
    pub dispatches: u64,
    pub bind_groups_created: u64,
    /// Nanoseconds the host spent in throttle waits: a step's host time less these is what
    /// recording and submitting it cost the CPU.
    pub throttle_wait_ns: u64,
    /// Nanoseconds in `queue.submit` (wgpu's tracking and the driver's submit, which on
    /// lavapipe blocks while the device is busy).
    pub submit_ns: u64,
}

impl std::ops::Sub for CounterSnapshot {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self {
            buffers_created: self.buffers_created - o.buffers_created,
            blocking_reads: self.blocking_reads - o.blocking_reads,
            throttle_waits: self.throttle_waits - o.throttle_waits,
            submissions: self.submissions - o.submissions,
            dispatches: self.dispatches - o.dispatches,
            bind_groups_created: self.bind_groups_created - o.bind_groups_created,
            throttle_wait_ns: self.throttle_wait_ns - o.throttle_wait_ns,
            submit_ns: self.submit_ns - o.submit_ns,
        }
    }
}

impl std::fmt::Display for CounterSnapshot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} buffers created, {} blocking reads, {} throttle waits, {} submissions, \
             {} dispatches, {} bind groups created",
            self.buffers_created,
            self.blocking_reads,
            self.throttle_waits,
            self.submissions,
            self.dispatches,
            self.bind_groups_created
        )
    }
}

fn nanos(d: std::time::Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

fn bump(c: &AtomicU64) {
    c.fetch_add(1, Ordering::Relaxed);
}

impl Counters {
    pub fn snapshot(&self) -> CounterSnapshot {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        CounterSnapshot {
            buffers_created: get(&self.buffers_created),
            blocking_reads: get(&self.blocking_reads),
            throttle_waits: get(&self.throttle_waits),
            submissions: get(&self.submissions),
            dispatches: get(&self.dispatches),
            bind_groups_created: get(&self.bind_groups_created),
            throttle_wait_ns: get(&self.throttle_wait_ns),
            submit_ns: get(&self.submit_ns),
        }
    }

    pub(crate) fn buffer_created(&self) {
        bump(&self.buffers_created);
    }
    pub(crate) fn blocking_read(&self) {
        bump(&self.blocking_reads);
    }
    pub(crate) fn throttle_wait(&self, waited: std::time::Duration) {
        bump(&self.throttle_waits);
        self.throttle_wait_ns
            .fetch_add(nanos(waited), Ordering::Relaxed);
    }
    pub(crate) fn submission(&self, took: std::time::Duration) {
        bump(&self.submissions);
        self.submit_ns.fetch_add(nanos(took), Ordering::Relaxed);
    }
    pub(crate) fn dispatch(&self) {
        bump(&self.dispatches);
    }
    pub(crate) fn bind_group_created(&self) {
        bump(&self.bind_groups_created);
    }
}
