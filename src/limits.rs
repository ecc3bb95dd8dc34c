//! Upper limits of the numeric options, checked by [`Options::validate`](crate::Options::validate) before anything is created on disk.
//! Each is far above any real use and far below what would overflow a size computation or a `Duration`.

/// `--window` (also the largest window `--contamination` may choose).
pub const WINDOW: usize = 1001;
/// `--downsample` block size K.
pub const DOWNSAMPLE: usize = 1024;
/// `--threads`.
pub const THREADS: usize = 1024;
/// `--degree` of `--method polynomial`.
pub const DEGREE: usize = 8;
/// `--idle-timeout`, seconds (a year).
pub const IDLE_TIMEOUT_S: f64 = 365.0 * 24.0 * 3600.0;
/// `--poll-interval`, milliseconds (an hour).
pub const POLL_INTERVAL_MS: u64 = 3_600_000;
/// `scatter-memory-mib` (1 TiB).
pub const SCATTER_MEMORY_MIB: usize = 1 << 20;
/// Shard count N of `--shard K/N`.
pub const SHARDS: usize = 1_000_000;
