//! How much memory this process may still take, so that a large file or a large registration is
//! refused with its size up front instead of aborting (Rust aborts on a failed allocation) or
//! spinning (OpenBLAS retries its own). Linux only; elsewhere nothing is known.
//!
//! Three limits count, the least wins: the memory the system has available (`MemAvailable`),
//! the process's address-space limit (`ulimit -v`, RLIMIT_AS) less the address space it already
//! maps, and its control group's limit (cgroup v2 `memory.max`, v1 `memory.limit_in_bytes`)
//! less the group's usage.

use std::path::{Path, PathBuf};

/// The bytes this process may still allocate, if any limit is known.
pub fn available() -> Option<u64> {
    [system(), address_space(), control_group()]
        .into_iter()
        .flatten()
        .min()
}

/// The first number of the line of `text` that starts with `key`, times `unit`.
fn field(text: &str, key: &str, unit: u64) -> Option<u64> {
    let line = text.lines().find(|l| l.starts_with(key))?;
    let value: u64 = line[key.len()..].split_whitespace().next()?.parse().ok()?;
    Some(value * unit)
}

/// Linux's MemAvailable.
fn system() -> Option<u64> {
    field(
        &std::fs::read_to_string("/proc/meminfo").ok()?,
        "MemAvailable:",
        1024,
    )
}

/// RLIMIT_AS less the address space mapped now (`VmSize`); `None` when unlimited.
fn address_space() -> Option<u64> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let limit = field(&limits, "Max address space", 1)?; // "unlimited" does not parse
    let mapped = field(
        &std::fs::read_to_string("/proc/self/status").ok()?,
        "VmSize:",
        1024,
    )?;
    Some(limit.saturating_sub(mapped))
}

/// The control group's limit less its usage; `None` when it has none.
fn control_group() -> Option<u64> {
    let membership = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let mut folders: Vec<(PathBuf, &str, &str)> = Vec::new(); // folder, limit file, usage file
    for line in membership.lines() {
        let mut parts = line.splitn(3, ':');
        let (_, controllers, path) = (parts.next()?, parts.next()?, parts.next()?);
        let path = path.trim_start_matches('/');
        if controllers.is_empty() {
            let root = Path::new("/sys/fs/cgroup");
            for folder in [root.join(path), root.to_path_buf()] {
                folders.push((folder, "memory.max", "memory.current"));
            }
        } else if controllers.split(',').any(|c| c == "memory") {
            let root = Path::new("/sys/fs/cgroup/memory");
            for folder in [root.join(path), root.to_path_buf()] {
                folders.push((folder, "memory.limit_in_bytes", "memory.usage_in_bytes"));
            }
        }
    }
    folders.iter().find_map(|(folder, limit, usage)| {
        let read = |name: &str| -> Option<u64> {
            std::fs::read_to_string(folder.join(name))
                .ok()?
                .trim()
                .parse()
                .ok()
        };
        // v2 writes "max" when unlimited (no number); v1 a number near 2^63.
        let limit = read(limit).filter(|&l| l < 1 << 62)?;
        Some(limit.saturating_sub(read(usage)?))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_are_read_with_their_unit() {
        let status = "Name:\trgm\nVmSize:\t  3892 kB\nVmRSS:\t 100 kB\n";
        assert_eq!(field(status, "VmSize:", 1024), Some(3892 * 1024));
        let limits = "Max address space         409600000            unlimited            bytes\n";
        assert_eq!(field(limits, "Max address space", 1), Some(409_600_000));
        let unlimited =
            "Max address space         unlimited            unlimited            bytes\n";
        assert_eq!(field(unlimited, "Max address space", 1), None);
    }

    #[test]
    fn this_machine_has_some_memory_available() {
        let bytes = available().expect("Linux says");
        assert!(bytes > 0 && bytes <= system().unwrap(), "{bytes}");
    }
}
