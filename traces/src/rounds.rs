//! How every benchmark times: the fastest of interleaved rounds.
//!
//! Each of the jobs a benchmark compares takes its turn in every one of `rounds` rounds; in
//! its turn a job runs until its runs add up to `min_seconds` (at least once), and its
//! figure is its fastest run over all rounds. A slow spell of a shared machine then falls on
//! every job alike instead of on whichever ran during it, and ratios between jobs measured
//! in the same rounds are what a benchmark prints.

use std::time::Instant;

/// A job's figure: its fastest run in seconds, the output of its last run, and its runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Timed<T> {
    pub seconds: f64,
    pub output: T,
    pub runs: usize,
}

/// Runs `jobs` in `rounds` interleaved rounds (each job's turn lasting at least
/// `min_seconds`, one run at least) and gives each job's [`Timed`] figure, in the jobs'
/// order. `rounds` is at least 1. Jobs of different types go in as `&mut dyn FnMut() -> T`.
pub fn fastest_of_rounds<T, F: FnMut() -> T>(
    rounds: usize,
    min_seconds: f64,
    jobs: &mut [F],
) -> Vec<Timed<T>> {
    let mut figures: Vec<Option<Timed<T>>> = jobs.iter().map(|_| None).collect();
    for _ in 0..rounds.max(1) {
        for (job, figure) in jobs.iter_mut().zip(&mut figures) {
            let mut spent = 0.0;
            loop {
                let start = Instant::now();
                let output = job();
                let seconds = start.elapsed().as_secs_f64();
                spent += seconds;
                *figure = Some(match figure.take() {
                    None => Timed {
                        seconds,
                        output,
                        runs: 1,
                    },
                    Some(best) => Timed {
                        seconds: best.seconds.min(seconds),
                        output,
                        runs: best.runs + 1,
                    },
                });
                if spent >= min_seconds {
                    break;
                }
            }
        }
    }
    figures
        .into_iter()
        .map(|f| f.expect("every job ran at least once"))
        .collect()
}

/// The one job's figure (a benchmark without a peer in the same run still takes rounds).
pub fn fastest_of<T>(rounds: usize, min_seconds: f64, mut job: impl FnMut() -> T) -> Timed<T> {
    fastest_of_rounds(rounds, min_seconds, &mut [&mut job])
        .pop()
        .expect("one job")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;
    use std::time::Duration;

    #[test]
    fn jobs_take_turns_and_keep_their_fastest_run() {
        let order = RefCell::new(Vec::new());
        let mut calls = 0;
        // Slow in the first round only: 30 ms, then 1 ms.
        let mut a = || {
            order.borrow_mut().push('a');
            calls += 1;
            std::thread::sleep(Duration::from_millis(if calls == 1 { 30 } else { 1 }));
            calls
        };
        let mut b = || {
            order.borrow_mut().push('b');
            0
        };
        let jobs: &mut [&mut dyn FnMut() -> usize] = &mut [&mut a, &mut b];
        let figures = fastest_of_rounds(3, 0.0, jobs);
        assert_eq!(
            order.into_inner(),
            ['a', 'b', 'a', 'b', 'a', 'b'],
            "interleaved"
        );
        assert_eq!(
            (figures[0].runs, figures[0].output),
            (3, 3),
            "the last run's output"
        );
        // The slow run sleeps at least 30 ms; the fastest is one of the 1 ms ones.
        assert!(
            figures[0].seconds < 0.030,
            "the fastest run: {}",
            figures[0].seconds
        );
        assert_eq!(figures[1].runs, 3);
    }

    #[test]
    fn a_turn_lasts_at_least_min_seconds() {
        let figure = fastest_of(2, 0.02, || std::thread::sleep(Duration::from_millis(5)));
        // Runs of at least 5 ms until 20 ms are spent: 1 to 4 a turn, two turns.
        assert!(figure.runs >= 2 && figure.runs <= 8, "{}", figure.runs);
        assert!(figure.seconds >= 0.005);
    }
}
