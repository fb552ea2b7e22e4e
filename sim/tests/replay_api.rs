//! The library replay API (`occsim_sim::replay`): a trace and options in, a level's result
//! out, with retiling, the effects choice and errors by stage, and no command line.

use occsim_sim::effects::EffectsChoice;
use occsim_sim::replay::{max_query_tiles, replay, ReplayError, ReplayOptions};
use occsim_sim::{Arch, Fidelity};
use occsim_traces::builtin::HARDCASES;
use occsim_traces::event::{Event, HostWork};
use occsim_traces::golden::EventSink;
use occsim_traces::golden::GoldenModel;
use occsim_traces::retile::TileGrid;
use occsim_traces::scene::parse_scene;
use occsim_traces::trace::{TraceHeader, TraceReader, TraceWriter};

fn hardcases_trace() -> Vec<u8> {
    hardcases_trace_after(&[])
}

/// The hard cases' trace, `first` written before them.
fn hardcases_trace_after(first: &[Event]) -> Vec<u8> {
    let lines = parse_scene(HARDCASES, "hardcases").expect("parses");
    let mut bytes = Vec::new();
    let mut writer = TraceWriter::new(&mut bytes, &TraceHeader::new(64, 64)).expect("header");
    let mut golden = GoldenModel::new(64, 64);
    for event in first {
        writer.event(event).unwrap();
    }
    for line in &lines {
        golden.execute(&line.command, &mut writer).unwrap();
    }
    golden.finish(&mut writer).unwrap();
    writer.finish().expect("written");
    bytes
}

#[test]
fn every_level_replays_from_bytes_and_the_effects_choice_changes_no_count() {
    let trace = hardcases_trace();
    let open = || Ok(TraceReader::new(&trace[..])?);
    for arch in ["o2", "ir4"] {
        let arch = Arch::builtin(arch).unwrap();
        let mut totals = Vec::new();
        for effects in [EffectsChoice::Auto, EffectsChoice::All] {
            let options = ReplayOptions {
                effects,
                ..ReplayOptions::at(Fidelity::Cycle)
            };
            let result = replay(open, &arch, options).expect("replays");
            // hardcases holds 28 queries (its comments number them).
            assert_eq!(result.queries.len(), 28);
            assert_eq!(result.checked_queries, 28);
            totals.push((result.total_cycles, result.queries.clone()));
        }
        assert_eq!(totals[0], totals[1], "auto and all effects differ");
        for level in [Fidelity::Functional, Fidelity::Analytic] {
            let result = replay(open, &arch, ReplayOptions::at(level)).expect("replays");
            assert_eq!(result.queries.len(), 28);
        }
    }
}

#[test]
fn errors_come_by_stage() {
    let trace = hardcases_trace();
    let arch = Arch::builtin("o2").unwrap();
    // A grid finer than the viewport: the retile stage refuses it.
    let options = ReplayOptions {
        retile: Some("65x1".parse::<TileGrid>().unwrap()),
        ..ReplayOptions::at(Fidelity::Cycle)
    };
    let error = replay(|| Ok(TraceReader::new(&trace[..])?), &arch, options).unwrap_err();
    assert!(matches!(error, ReplayError::Retile { .. }), "{error:?}");
    // A truncated trace: the read stage, with the byte offset.
    let cut = &trace[..trace.len() / 2];
    let error = replay(
        || Ok(TraceReader::new(cut)?),
        &arch,
        ReplayOptions::cycle(None),
    )
    .unwrap_err();
    assert!(matches!(error, ReplayError::Read(_)), "{error:?}");
    // The waveform's slot count: a trace written to memory has no features in its header,
    // so it comes from a scan (hardcases' largest query has 5 tiles).
    let tiles = max_query_tiles(|| Ok(TraceReader::new(&trace[..])?), &arch).unwrap();
    assert_eq!(tiles, 5);
}

#[test]
fn a_simulated_time_past_what_a_report_can_sum_is_an_error_not_a_wrapped_count() {
    // The hard cases after host work of 2^32 - 1 nodes at 2^24 host cycles each, on a host
    // of 0.001 MHz against a pipe of 100,000 MHz: 7.2e24 pipeline cycles, past 2^62 (each
    // parameter within its range). Summed, the cycle counts had wrapped past 2^64 and been
    // reported with exit 0.
    let work = HostWork {
        nodes: u32::MAX,
        ..HostWork::default()
    };
    let trace = hardcases_trace_after(&[Event::HostWork(work)]);
    let open = || Ok(TraceReader::new(&trace[..])?);
    for machine in ["o2", "ir4"] {
        let mut arch = Arch::builtin(machine).unwrap();
        for setting in [
            "host_clock_mhz=0.001",
            "clock_mhz=100000",
            "host_cycles_per_node=16777216",
        ] {
            arch.set(setting).unwrap();
        }
        for level in [
            Fidelity::Analytic,
            Fidelity::Cycle,
            Fidelity::Sampled { every: 10 },
        ] {
            let error = replay(open, &arch, ReplayOptions::at(level))
                .map(|result| result.total_cycles)
                .expect_err("refused");
            let source = std::error::Error::source(&error).map(ToString::to_string);
            assert!(
                source.as_deref().unwrap_or("").contains("past the 2^62"),
                "{machine} {level:?}: {error}: {source:?}"
            );
        }
        // Within range, the same trace replays.
        let arch = Arch::builtin(machine).unwrap();
        replay(open, &arch, ReplayOptions::at(Fidelity::Cycle)).expect("replays");
    }
}

#[test]
fn the_cycle_level_keeps_every_tiles_report_only_when_asked_and_its_totals_always() {
    // Kept for every query, the tiles' reports had taken 300 queries of 65,536 tiles each
    // 1.1 GB at the cycle level (17 MB functional); a level's result takes the totals.
    let trace = hardcases_trace();
    let open = || Ok(TraceReader::new(&trace[..])?);
    for machine in ["o2", "ir4"] {
        let arch = Arch::builtin(machine).unwrap();
        let totals_only = replay(open, &arch, ReplayOptions::at(Fidelity::Cycle)).unwrap();
        let every_tile = ReplayOptions {
            tile_reports: true,
            ..ReplayOptions::at(Fidelity::Cycle)
        };
        let with_tiles = replay(open, &arch, every_tile).unwrap();
        let (lean, full) = (
            totals_only.report.as_ref().expect("a report"),
            with_tiles.report.as_ref().expect("a report"),
        );
        assert_eq!(totals_only.queries, with_tiles.queries, "{machine}");
        assert_eq!(
            totals_only.total_cycles, with_tiles.total_cycles,
            "{machine}"
        );
        for (lean, full) in lean.queries.iter().zip(&full.queries) {
            assert!(lean.tiles.is_empty(), "{machine}");
            assert_eq!(full.tiles.len(), full.totals.tiles, "{machine}");
            assert_eq!(lean.totals, full.totals, "{machine}");
            let nohc: u64 = full.tiles.iter().map(|tile| tile.nohc).sum();
            let phc: u64 = full.tiles.iter().map(|tile| tile.phc).sum();
            let hits: u64 = full.tiles.iter().map(|tile| tile.hits_written).sum();
            assert_eq!(
                (nohc, phc, hits),
                (full.totals.nohc, full.totals.phc, full.totals.hits_written),
                "{machine}"
            );
        }
    }
}
