//! The memory a command may use: the least of the machine's available
//! memory (or [`super::LIMIT_ENV`] in its place) and every hard limit the
//! process runs under. A container's cgroup (`memory.max` in cgroup v2,
//! `memory.limit_in_bytes` in v1: every Kubernetes pod with a memory limit
//! has one) and an address-space limit (`ulimit -v`, `ulimit -d`) end a
//! command that passes the machine's `MemAvailable`: the kernel's OOM
//! killer in the first case, `memory allocation of N bytes failed` and an
//! abort in the second. Both are read here so that the estimate is refused
//! before anything is allocated, naming the limit that refused it.

use std::path::{Path, PathBuf};

use super::LIMIT_ENV;
use crate::{Error, Result};

/// A bound on the memory a command may still allocate, and where it comes
/// from, in words for messages.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Limit {
    /// Bytes the command may still allocate under this limit.
    pub bytes: u128,
    /// Where it comes from: the file or setting, with its value and use.
    pub from: String,
    /// Whether [`LIMIT_ENV`] cannot raise it (a cgroup's or an rlimit).
    pub hard: bool,
}

/// The least limit in force: [`LIMIT_ENV`] if set, else the available
/// memory, and below either every hard limit ([`hard_limits`]); `None`
/// when none is known (no `/proc`).
pub fn limit() -> Result<Option<Limit>> {
    let soft = if let Some(v) = std::env::var_os(LIMIT_ENV) {
        let s = v.to_string_lossy();
        let bytes = parse_bytes(&s).ok_or_else(|| {
            Error::InvalidSize(format!(
                "{LIMIT_ENV}={s}: expected a number of bytes, optionally with a K, M, G or T suffix"
            ))
        })?;
        Some(Limit {
            bytes,
            from: format!("{LIMIT_ENV}={s}"),
            hard: false,
        })
    } else {
        available().map(|bytes| Limit {
            bytes,
            from: "the memory available (MemAvailable)".to_string(),
            hard: false,
        })
    };
    Ok(least(soft.into_iter().chain(hard_limits())))
}

/// The least of `limits`; of equal ones, the first.
fn least(limits: impl Iterator<Item = Limit>) -> Option<Limit> {
    limits.fold(None, |best: Option<Limit>, l| match best {
        Some(b) if b.bytes <= l.bytes => Some(b),
        _ => Some(l),
    })
}

/// Every hard limit on this process's memory, each as what is left under
/// it: the memory cgroup at every level from the process's own to the
/// hierarchy's root (v1 and v2), less what the group uses apart from its
/// inactive file cache (which the kernel reclaims before it kills); the
/// address-space limit less `VmSize`; the data-segment limit less `VmData`.
pub fn hard_limits() -> Vec<Limit> {
    let read = |p: &Path| std::fs::read_to_string(p).ok();
    let mut all = Vec::new();
    if let (Some(mounts), Some(groups)) = (
        read(Path::new("/proc/self/mountinfo")),
        read(Path::new("/proc/self/cgroup")),
    ) {
        all.extend(cgroup_limits(&mounts, &groups, &read));
    }
    if let (Some(limits), Some(status)) = (
        read(Path::new("/proc/self/limits")),
        read(Path::new("/proc/self/status")),
    ) {
        all.extend(rlimit_limits(&limits, &status));
    }
    all
}

/// A cgroup v1 limit at or above this is no limit (the kernel writes
/// `PAGE_COUNTER_MAX` pages, 9223372036854771712 bytes with 4 KiB pages).
const V1_UNLIMITED: u128 = 1 << 62;

/// The memory cgroups' limits from the text of `/proc/self/mountinfo` and
/// `/proc/self/cgroup`, reading the controllers' files through `read`.
pub(crate) fn cgroup_limits(
    mountinfo: &str,
    cgroups: &str,
    read: &dyn Fn(&Path) -> Option<String>,
) -> Vec<Limit> {
    let mut out = Vec::new();
    for line in mountinfo.lines() {
        let Some((left, right)) = line.split_once(" - ") else {
            continue;
        };
        let left: Vec<&str> = left.split_whitespace().collect();
        let right: Vec<&str> = right.split_whitespace().collect();
        let (Some(root), Some(mount), Some(fstype)) = (left.get(3), left.get(4), right.first())
        else {
            continue;
        };
        let v2 = *fstype == "cgroup2";
        let v1 = *fstype == "cgroup"
            && right
                .get(2)
                .is_some_and(|o| o.split(',').any(|o| o == "memory"));
        if !v1 && !v2 {
            continue;
        }
        let Some(path) = cgroups.lines().find_map(|l| {
            let mut f = l.splitn(3, ':');
            let (_, controllers, path) = (f.next()?, f.next()?, f.next()?);
            let ours = if v2 {
                controllers.is_empty()
            } else {
                controllers.split(',').any(|c| c == "memory")
            };
            ours.then_some(path)
        }) else {
            continue;
        };
        let root = unescape(root);
        let mount = PathBuf::from(unescape(mount));
        // The group's path relative to what is mounted: a container sees
        // its own group at the mount point when the mount's root is it.
        let rel = if root == "/" {
            path
        } else if let Some(rest) = path.strip_prefix(root.as_str()) {
            if !(rest.is_empty() || rest.starts_with('/')) {
                continue;
            }
            rest
        } else {
            continue;
        };
        let mut dir = mount.clone();
        for part in rel.split('/').filter(|p| !p.is_empty() && *p != "..") {
            dir.push(part);
        }
        loop {
            if let Some(l) = if v2 {
                group_limit_v2(&dir, read)
            } else {
                group_limit_v1(&dir, read)
            } {
                out.push(l);
            }
            if dir == mount || !dir.pop() || !dir.starts_with(&mount) {
                break;
            }
        }
    }
    out
}

/// A cgroup v2 group's `memory.max` less its use.
fn group_limit_v2(dir: &Path, read: &dyn Fn(&Path) -> Option<String>) -> Option<Limit> {
    let max: u128 = read(&dir.join("memory.max"))?.trim().parse().ok()?;
    let current: u128 = read(&dir.join("memory.current"))
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(0);
    let inactive = stat_value(read(&dir.join("memory.stat")), "inactive_file");
    Some(group_limit(dir.join("memory.max"), max, current, inactive))
}

/// A cgroup v1 group's `memory.limit_in_bytes` less its use.
fn group_limit_v1(dir: &Path, read: &dyn Fn(&Path) -> Option<String>) -> Option<Limit> {
    let max: u128 = read(&dir.join("memory.limit_in_bytes"))?
        .trim()
        .parse()
        .ok()?;
    if max >= V1_UNLIMITED {
        return None;
    }
    let usage: u128 = read(&dir.join("memory.usage_in_bytes"))
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(0);
    let inactive = stat_value(read(&dir.join("memory.stat")), "total_inactive_file");
    Some(group_limit(
        dir.join("memory.limit_in_bytes"),
        max,
        usage,
        inactive,
    ))
}

fn group_limit(file: PathBuf, max: u128, usage: u128, inactive: u128) -> Limit {
    let used = usage.saturating_sub(inactive);
    Limit {
        bytes: max.saturating_sub(used),
        from: format!(
            "what is left under the cgroup limit {} ({} of which {} in use)",
            file.display(),
            super::human(max),
            super::human(used)
        ),
        hard: true,
    }
}

/// The value of `key` in a `memory.stat` file, 0 when absent.
fn stat_value(stat: Option<String>, key: &str) -> u128 {
    stat.and_then(|s| {
        s.lines().find_map(|l| {
            let (k, v) = l.split_once(' ')?;
            (k == key).then(|| v.trim().parse().ok()).flatten()
        })
    })
    .unwrap_or(0)
}

/// `/proc/self/mountinfo` writes a space, tab, newline and backslash in a
/// path as octal escapes (`\040`).
fn unescape(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'\\'
            && i + 3 < b.len()
            && b[i + 1..i + 4].iter().all(|c| (b'0'..=b'7').contains(c))
        {
            let v = b[i + 1..i + 4]
                .iter()
                .fold(0u32, |v, c| v * 8 + u32::from(c - b'0'));
            out.push(v as u8);
            i += 4;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The address-space and data-segment limits from the text of
/// `/proc/self/limits` (soft limits, which are the ones enforced), less
/// `VmSize` and `VmData` of `/proc/self/status`.
pub(crate) fn rlimit_limits(limits: &str, status: &str) -> Vec<Limit> {
    [
        ("Max address space", "VmSize:", "ulimit -v", "address-space"),
        ("Max data size", "VmData:", "ulimit -d", "data-segment"),
    ]
    .into_iter()
    .filter_map(|(name, vm, shell, kind)| {
        let soft: u128 = limits
            .lines()
            .find_map(|l| l.strip_prefix(name))?
            .split_whitespace()
            .next()?
            .parse()
            .ok()?;
        let used = status
            .lines()
            .find_map(|l| l.strip_prefix(vm))
            .and_then(kib)
            .unwrap_or(0);
        Some(Limit {
            bytes: soft.saturating_sub(used),
            from: format!(
                "what is left under the {kind} limit ({shell}: {}, of which {} {} in use)",
                super::human(soft),
                vm.trim_end_matches(':'),
                super::human(used)
            ),
            hard: true,
        })
    })
    .collect()
}

/// `  123 kB` in bytes.
fn kib(s: &str) -> Option<u128> {
    let mut words = s.split_whitespace();
    let n: u128 = words.next()?.parse().ok()?;
    match words.next() {
        Some("kB") => Some(n * 1024),
        None => Some(n),
        _ => None,
    }
}

/// `MemAvailable` of `/proc/meminfo`, in bytes.
pub fn available() -> Option<u128> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    meminfo_available(&info)
}

fn meminfo_available(info: &str) -> Option<u128> {
    kib(info.lines().find_map(|l| l.strip_prefix("MemAvailable:"))?)
}

/// `123`, `64K`, `1.5G`, `2T` (powers of 1024; a trailing `B` or `iB` is
/// allowed).
pub fn parse_bytes(s: &str) -> Option<u128> {
    let s = s.trim();
    let s = s
        .strip_suffix("iB")
        .or_else(|| s.strip_suffix('B'))
        .unwrap_or(s);
    let (num, scale) = match s.char_indices().last()? {
        (i, c) if c.is_ascii_alphabetic() => {
            let power = match c.to_ascii_uppercase() {
                'K' => 1,
                'M' => 2,
                'G' => 3,
                'T' => 4,
                _ => return None,
            };
            (&s[..i], 1024f64.powi(power))
        }
        _ => (s, 1.0),
    };
    let v: f64 = num.trim().parse().ok()?;
    (v.is_finite() && v >= 0.0).then_some((v * scale) as u128)
}

/// `1.5 GiB`, for messages.
pub fn human(bytes: u128) -> String {
    let mut v = bytes as f64;
    for unit in ["bytes", "KiB", "MiB", "GiB"] {
        if v < 1024.0 {
            return if unit == "bytes" {
                format!("{bytes} bytes")
            } else {
                format!("{v:.1} {unit}")
            };
        }
        v /= 1024.0;
    }
    format!("{v:.1} TiB")
}

/// Refuses `what` (a description of the job, such as `bake of a 46000x46000
/// height map into 32x32x8 voxels`) when its estimated peak of `bytes`
/// exceeds the least [`limit`], naming the estimate, the limit and how to
/// raise it (or that [`LIMIT_ENV`] cannot).
pub fn check(what: &str, bytes: u128) -> Result<()> {
    let Some(l) = limit()? else {
        return Ok(());
    };
    if bytes <= l.bytes {
        return Ok(());
    }
    let raise = if l.hard {
        format!("that is a hard limit, which {LIMIT_ENV} cannot raise: raise the limit itself, or ask for less")
    } else {
        format!("set {LIMIT_ENV}=BYTES (such as 64G) to allow more")
    };
    Err(Error::OutOfMemory {
        message: format!(
            "{what} needs about {} ({bytes} bytes), more than {}: {} ({} bytes); {raise}",
            human(bytes),
            l.from,
            human(l.bytes),
            l.bytes
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_bytes("123"), Some(123));
        assert_eq!(parse_bytes("64K"), Some(64 << 10));
        assert_eq!(parse_bytes("2g"), Some(2 << 30));
        assert_eq!(parse_bytes("1.5GiB"), Some(3 << 29));
        assert_eq!(parse_bytes("1T"), Some(1 << 40));
        assert_eq!(parse_bytes("lots"), None);
        assert_eq!(parse_bytes("-1"), None);
        assert_eq!(parse_bytes("4X"), None);
    }

    #[test]
    fn meminfo_is_read_in_kib() {
        let info = "MemTotal:       24000000 kB\nMemFree:  1 kB\nMemAvailable:   22000000 kB\n";
        assert_eq!(meminfo_available(info), Some(22_000_000 * 1024));
        assert_eq!(meminfo_available("MemTotal: 1 kB\n"), None);
    }

    #[test]
    fn human_sizes() {
        assert_eq!(human(512), "512 bytes");
        assert_eq!(human(3 << 29), "1.5 GiB");
    }

    fn files(entries: &[(&str, &str)]) -> impl Fn(&Path) -> Option<String> {
        let map: HashMap<PathBuf, String> = entries
            .iter()
            .map(|(p, s)| (PathBuf::from(p), s.to_string()))
            .collect();
        move |p: &Path| map.get(p).cloned()
    }

    const V2_MOUNT: &str =
        "30 23 0:26 / /sys/fs/cgroup rw,nosuid - cgroup2 cgroup2 rw,nsdelegate\n";

    /// A cgroup v2 pod: its own group's limit less its use without the
    /// inactive file cache, and its parent's, whichever leaves less.
    #[test]
    fn cgroup_v2_limits_at_every_level() {
        let read = files(&[
            ("/sys/fs/cgroup/kubepods/pod1/memory.max", "8589934592\n"),
            (
                "/sys/fs/cgroup/kubepods/pod1/memory.current",
                "3221225472\n",
            ),
            (
                "/sys/fs/cgroup/kubepods/pod1/memory.stat",
                "anon 1073741824\nfile 2147483648\ninactive_file 2147483648\nactive_file 0\n",
            ),
            ("/sys/fs/cgroup/kubepods/memory.max", "max\n"),
            ("/sys/fs/cgroup/memory.max", "4294967296\n"),
            ("/sys/fs/cgroup/memory.current", "1073741824\n"),
        ]);
        let l = cgroup_limits(V2_MOUNT, "0::/kubepods/pod1\n", &read);
        assert_eq!(l.len(), 2, "{l:?}");
        assert_eq!(l[0].bytes, (8 << 30) - (1 << 30));
        assert!(l[0]
            .from
            .contains("/sys/fs/cgroup/kubepods/pod1/memory.max"));
        assert!(
            l[0].from.contains("8.0 GiB of which 1.0 GiB in use"),
            "{}",
            l[0].from
        );
        assert_eq!(l[1].bytes, 3 << 30);
        assert!(l.iter().all(|l| l.hard));
        assert_eq!(least(l.into_iter()).unwrap().bytes, 3 << 30);
        // No limit anywhere: none.
        let read = files(&[("/sys/fs/cgroup/memory.max", "max\n")]);
        assert!(cgroup_limits(V2_MOUNT, "0::/\n", &read).is_empty());
    }

    /// Inside a container whose cgroup namespace or mount shows only its own
    /// group: the mount's root is the group, and its path is the mount point.
    #[test]
    fn cgroup_mount_roots_inside_containers() {
        let read = files(&[
            (
                "/sys/fs/cgroup/memory/memory.limit_in_bytes",
                "2147483648\n",
            ),
            ("/sys/fs/cgroup/memory/memory.usage_in_bytes", "536870912\n"),
            (
                "/sys/fs/cgroup/memory/memory.stat",
                "cache 0\ninactive_file 1\ntotal_inactive_file 268435456\n",
            ),
        ]);
        let mounts =
            "35 31 0:32 /docker/abc /sys/fs/cgroup/memory ro,nosuid - cgroup cgroup rw,memory\n\
                      36 31 0:33 /docker/abc /sys/fs/cgroup/cpu ro - cgroup cgroup rw,cpu\n";
        let l = cgroup_limits(mounts, "5:cpu:/docker/abc\n4:memory:/docker/abc\n", &read);
        assert_eq!(l.len(), 1, "{l:?}");
        assert_eq!(l[0].bytes, (2 << 30) - (256 << 20));
        assert!(l[0].from.contains("memory.limit_in_bytes"));
        // A group outside the mount's root is not this mount's.
        assert!(cgroup_limits(mounts, "4:memory:/other\n", &read).is_empty());
        // v1's "unlimited" is no limit.
        let read = files(&[(
            "/sys/fs/cgroup/memory/memory.limit_in_bytes",
            "9223372036854771712\n",
        )]);
        assert!(cgroup_limits(mounts, "4:memory:/docker/abc\n", &read).is_empty());
    }

    /// A group whose use already passes its limit leaves nothing, and a
    /// mount point with a space in it is unescaped.
    #[test]
    fn cgroup_overuse_and_escaped_paths() {
        let read = files(&[
            ("/mnt/c g/memory.max", "100\n"),
            ("/mnt/c g/memory.current", "500\n"),
        ]);
        let mounts = "1 1 0:1 / /mnt/c\\040g rw - cgroup2 none rw\n";
        let l = cgroup_limits(mounts, "0::/\n", &read);
        assert_eq!(l.len(), 1);
        assert_eq!(l[0].bytes, 0);
    }

    #[test]
    fn rlimits_less_what_is_mapped() {
        let limits = "Limit                     Soft Limit           Hard Limit           Units     \n\
                      Max data size             unlimited            unlimited            bytes     \n\
                      Max address space         1073741824           unlimited            bytes     \n";
        let status =
            "Name:\tdisplace\nVmPeak:\t  300000 kB\nVmSize:\t  262144 kB\nVmData:\t 1024 kB\n";
        let l = rlimit_limits(limits, status);
        assert_eq!(l.len(), 1, "{l:?}");
        assert_eq!(l[0].bytes, (1 << 30) - (256 << 20));
        assert!(
            l[0].from
                .contains("ulimit -v: 1.0 GiB, of which VmSize 256.0 MiB in use"),
            "{}",
            l[0].from
        );
        assert!(l[0].hard);
        let unlimited = limits.replace("1073741824 ", "unlimited  ");
        assert!(rlimit_limits(&unlimited, status).is_empty());
    }

    /// The soft limit (the environment variable or `MemAvailable`) gives way
    /// to a smaller hard one, and a refusal names which it was.
    #[test]
    fn the_least_limit_is_the_one_named() {
        let soft = Limit {
            bytes: 100,
            from: "soft".into(),
            hard: false,
        };
        let hard = Limit {
            bytes: 50,
            from: "hard".into(),
            hard: true,
        };
        assert_eq!(
            least([soft.clone(), hard.clone()].into_iter()),
            Some(hard.clone())
        );
        assert_eq!(least([soft.clone()].into_iter()), Some(soft));
        assert_eq!(least(std::iter::empty()), None);
    }
}
