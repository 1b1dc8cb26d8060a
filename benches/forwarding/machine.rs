//! What the machine says about itself: CPU model, jiffies, steal time, interrupts.

pub(crate) fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_owned())
        })
        .unwrap_or_else(|| "unknown".into())
}

/// The whole machine's times, in jiffies: the `cpu` line of /proc/stat (user, nice, system,
/// idle, iowait, irq, softirq, steal, …).
pub(crate) fn machine_times() -> Vec<u64> {
    let stat = std::fs::read_to_string("/proc/stat").unwrap_or_default();
    stat.lines()
        .next()
        .unwrap_or("")
        .split_whitespace()
        .skip(1)
        .filter_map(|x| x.parse().ok())
        .collect()
}

/// Busy and total jiffies of the whole machine, from /proc/stat.
pub(crate) fn machine_jiffies() -> (u64, u64) {
    let v = machine_times();
    let total: u64 = v.iter().take(8).sum();
    let idle = v.get(3).copied().unwrap_or(0) + v.get(4).copied().unwrap_or(0);
    (total - idle, total)
}

/// `USER_HZ`: the unit of /proc/stat's times on Linux.
pub(crate) const JIFFIES_PER_S: f64 = 100.0;

pub(crate) fn cpus() -> f64 {
    std::thread::available_parallelism().map_or(1.0, |n| n.get() as f64)
}

/// Jiffies the hypervisor took from the machine's CPUs (`steal`, /proc/stat's eighth time).
pub(crate) fn steal_jiffies() -> u64 {
    machine_times().get(7).copied().unwrap_or(0)
}

/// Interrupts between CPUs so far, all CPUs: the RES, CAL and TLB lines of /proc/interrupts.
pub(crate) fn ipis() -> u64 {
    let text = std::fs::read_to_string("/proc/interrupts").unwrap_or_default();
    text.lines()
        .filter_map(|l| {
            let (name, rest) = l.trim_start().split_once(':')?;
            ["RES", "CAL", "TLB"].contains(&name).then_some(rest)
        })
        .flat_map(|rest| rest.split_whitespace().map_while(|x| x.parse::<u64>().ok()))
        .sum()
}

/// CPU jiffies of this process and its reaped children (the forwarders).
pub(crate) fn own_jiffies() -> u64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    rest.split_whitespace()
        .skip(11)
        .take(4)
        .filter_map(|x| x.parse::<u64>().ok())
        .sum()
}
