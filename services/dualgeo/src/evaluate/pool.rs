//! The evaluation's independent flights (noise passes, Monte Carlo seeds) one per
//! core at a time. Each job's result is the same whichever thread
//! runs it: every flight owns its stream, chain and random generators.

use anyhow::Result;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// Runs `work(index, job)` on every job, as many at a time as there are cores, and
/// returns the results in the jobs' order. The first error stops the jobs not yet
/// started and is returned.
pub fn on_every_core<J: Sync, T: Send>(
    jobs: &[J],
    work: impl Fn(usize, &J) -> Result<T> + Sync,
) -> Result<Vec<T>> {
    let threads = std::thread::available_parallelism()
        .map_or(2, |n| n.get())
        .min(jobs.len().max(1));
    let slots: Vec<Mutex<Option<T>>> = jobs.iter().map(|_| Mutex::new(None)).collect();
    let failure: Mutex<Option<anyhow::Error>> = Mutex::new(None);
    let next = AtomicUsize::new(0);
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(job) = jobs.get(i) else { break };
                if failure.lock().map_or(true, |f| f.is_some()) {
                    break;
                }
                match work(i, job) {
                    Ok(r) => {
                        if let Ok(mut slot) = slots[i].lock() {
                            *slot = Some(r);
                        }
                    }
                    Err(e) => {
                        if let Ok(mut f) = failure.lock() {
                            f.get_or_insert(e);
                        }
                    }
                }
            });
        }
    });
    if let Some(e) = failure.into_inner().ok().flatten() {
        return Err(e);
    }
    slots
        .into_iter()
        .enumerate()
        .map(|(i, slot)| {
            slot.into_inner()
                .ok()
                .flatten()
                .ok_or_else(|| anyhow::anyhow!("evaluation job {i} gave no result"))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_come_back_in_the_jobs_order() {
        let jobs: Vec<u64> = (0..50).collect();
        let out = on_every_core(&jobs, |i, j| {
            // Uneven work, so the threads finish out of order.
            std::thread::sleep(std::time::Duration::from_millis((j * 7) % 5));
            Ok((i, j * j))
        })
        .unwrap();
        assert_eq!(
            out,
            jobs.iter()
                .map(|&j| (j as usize, j * j))
                .collect::<Vec<_>>()
        );
    }

    #[test]
    fn an_error_is_returned_and_stops_the_jobs_not_started() {
        let jobs: Vec<u64> = (0..1000).collect();
        let ran = AtomicUsize::new(0);
        let r = on_every_core(&jobs, |_, &j| {
            ran.fetch_add(1, Ordering::Relaxed);
            if j == 3 {
                anyhow::bail!("job 3 failed");
            }
            std::thread::sleep(std::time::Duration::from_millis(1));
            Ok(j)
        });
        assert_eq!(r.unwrap_err().to_string(), "job 3 failed");
        assert!(ran.load(Ordering::Relaxed) < 1000);
    }
}
