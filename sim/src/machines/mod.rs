//! A machine model of whichever kind the architecture names: the one entry point the command
//! line, sweeps and latency reports replay traces through.

pub mod builder;
pub mod closed_loop;
pub mod ir;
pub mod o2;

pub use builder::MachineBuilder;

use crate::arch::{Arch, Machine};
use crate::blocks::geometry::Geometry;
use crate::blocks::host::{Host, HostCosts};
use crate::blocks::merge_network::MergeState;
use crate::error::SimError;
use crate::machines::closed_loop::{ClosedLoop, PipeState};
use crate::machines::ir::IrMachine;
use crate::machines::o2::O2Machine;
use crate::report::Report;
use occsim_traces::golden::DepthBuffer;
use occsim_traces::state::RenderState;
use occsim_traces::{Event, Span};
use std::collections::HashMap;

/// A machine being replayed: its pixel pipeline and the closed loop that feeds it.
pub struct MachineModel {
    pipe: Pipe,
    front: ClosedLoop,
    /// Events fed so far (the index of the next, for errors).
    events: u64,
    /// Started mid-stream (the sampled level's windows).
    resumed: Option<Resumed>,
}

/// What a machine started mid-stream knows of the stream before it.
#[derive(Default)]
struct Resumed {
    /// The cycle of the timeline its host was taken up from where its clock starts
    /// ([`MachineModel::resume_front`]).
    base: u64,
    /// Answers (available cycle, on its clock, and record words) of queries that ended
    /// before its start ([`MachineModel::take_answer`]); any other such query is taken as
    /// answered at the start.
    answers: HashMap<u32, (u64, u64)>,
}

/// The pixel pipeline of either kind.
// One per replay, never in a collection: boxing would only add an indirection per event.
#[allow(clippy::large_enum_variant)]
enum Pipe {
    O2(O2Machine),
    Ir(IrMachine),
}

impl Pipe {
    fn release(&mut self, cycle: u64) -> Result<(), SimError> {
        match self {
            Pipe::O2(m) => m.release(cycle),
            Pipe::Ir(m) => {
                m.release(cycle);
                Ok(())
            }
        }
    }

    fn state(&mut self) -> Result<PipeState, SimError> {
        Ok(match self {
            Pipe::O2(m) => PipeState {
                idle_cycle: m.drain()?,
                raster_busy_cycles: m.raster_busy_cycles(),
            },
            Pipe::Ir(m) => PipeState {
                idle_cycle: m.drain()?,
                raster_busy_cycles: m.raster_busy_cycles(),
            },
        })
    }

    fn result_available(&mut self, id: u32) -> Result<Option<(u64, u64)>, SimError> {
        match self {
            Pipe::O2(m) => m.result_available(id),
            Pipe::Ir(m) => m.result_available(id),
        }
    }
}

/// The host of a machine's parameters (both tables name the host's parameters alike).
macro_rules! host_of {
    ($a:expr) => {
        Host::new(HostCosts::from_host_cycles(
            $a.host_clock_mhz,
            $a.clock_mhz,
            [
                $a.host_cycles_per_node,
                $a.host_cycles_per_box_test,
                $a.host_cycles_per_decision,
                $a.host_cycles_per_draw,
                $a.host_cycles_per_readback_pixel,
                $a.host_cycles_per_state_change,
            ],
        ))
    };
}

/// The closed loop `arch` describes: its host, geometry stage and result path.
pub(crate) fn closed_loop_of(arch: &Arch) -> Result<ClosedLoop, SimError> {
    Ok(match arch.machine() {
        Machine::O2 => {
            let a = arch.o2()?;
            let scale = a.clock_mhz / a.host_clock_mhz;
            ClosedLoop::new(
                host_of!(a),
                Geometry::OnHost {
                    per_vertex: a.geometry_host_cycles_per_vertex as f64 * scale,
                    per_triangle: a.geometry_host_cycles_per_triangle as f64 * scale,
                },
                a.result_notify_latency_cycles,
                a.result_read_cycles_per_word,
                a.clock_mhz,
            )
        }
        Machine::Ir => {
            let a = arch.ir()?;
            let ge_scale = a.clock_mhz / a.geometry_engine_clock_mhz;
            // Bytes over MB/s is microseconds; times the clock in MHz, cycles.
            let bus_per_vertex =
                a.bus_bytes_per_vertex as f64 / a.bus_megabytes_per_second * a.clock_mhz;
            ClosedLoop::new(
                host_of!(a),
                Geometry::Engines {
                    per_vertex: a.geometry_engine_cycles_per_vertex as f64 * ge_scale,
                    per_triangle: a.geometry_engine_cycles_per_triangle as f64 * ge_scale,
                    bus_per_vertex,
                    free: vec![0; a.geometry_engines],
                    last_release: 0,
                },
                a.result_notify_latency_cycles,
                a.result_read_cycles_per_word,
                a.clock_mhz,
            )
        }
    })
}

impl<'a> MachineBuilder<'a> {
    /// The machine at reset for a `width` x `height` viewport.
    pub fn build(self, width: u32, height: u32) -> Result<MachineModel, SimError> {
        let mut front = closed_loop_of(self.arch)?;
        front.host.timeline = self.timeline.clone();
        let pipe = match self.arch.machine() {
            Machine::O2 => Pipe::O2(self.o2(width, height)?),
            Machine::Ir => Pipe::Ir(self.ir(width, height)?),
        };
        Ok(MachineModel::of(pipe, front))
    }

    /// The machine started from a functional model's render state and depths (the sampled
    /// level's machines, started mid-stream). `storage`, a buffer a finished machine handed
    /// back ([`MachineModel::finish_recycling`]), is reused for the copy of `depth` when
    /// given.
    pub fn resume(
        self,
        state: &RenderState,
        depth: &DepthBuffer,
        storage: Option<DepthBuffer>,
    ) -> Result<MachineModel, SimError> {
        let mut copy = match storage {
            Some(storage) => storage,
            None => DepthBuffer::try_unset(state.width, state.height)?,
        };
        copy.copy_from(depth);
        self.resume_with_depths(state, copy)
    }

    /// [`Self::resume`] with `depth` taken as the machine's depth buffer, not copied (the
    /// sampled level's consistent depths fill it as the machine goes,
    /// [`crate::levels::consistent_depths`]).
    pub fn resume_with_depths(
        self,
        state: &RenderState,
        copy: DepthBuffer,
    ) -> Result<MachineModel, SimError> {
        let (width, height) = (state.width, state.height);
        crate::error::check_viewport(width, height)?;
        let front = closed_loop_of(self.arch)?;
        let pipe = match self.arch.machine() {
            Machine::O2 => Pipe::O2(O2Machine::assemble(self, width, height, copy, Some(state))?),
            Machine::Ir => Pipe::Ir(IrMachine::assemble(self, width, height, copy, Some(state))?),
        };
        let mut machine = MachineModel::of(pipe, front);
        machine.resumed = Some(Resumed::default());
        Ok(machine)
    }

    /// The O2-like machine at reset (an error when the architecture names another).
    pub fn o2(self, width: u32, height: u32) -> Result<O2Machine, SimError> {
        crate::error::check_viewport(width, height)?;
        let depth = DepthBuffer::try_new(width, height)?;
        O2Machine::assemble(self, width, height, depth, None)
    }

    /// The InfiniteReality-like machine at reset (an error when the architecture names
    /// another).
    pub fn ir(self, width: u32, height: u32) -> Result<IrMachine, SimError> {
        self.arch.ir()?;
        crate::error::check_viewport(width, height)?;
        let depth = DepthBuffer::try_new(width, height)?;
        IrMachine::assemble(self, width, height, depth, None)
    }
}

impl MachineModel {
    /// The machine `arch` describes at reset: shorthand for [`MachineBuilder::build`] with
    /// every effect modelled and the OccU at the cycle level.
    pub fn new(arch: &Arch, width: u32, height: u32) -> Result<MachineModel, SimError> {
        MachineBuilder::new(arch).build(width, height)
    }

    fn of(pipe: Pipe, front: ClosedLoop) -> MachineModel {
        MachineModel {
            pipe,
            front,
            events: 0,
            resumed: None,
        }
    }

    /// Whether each query's report keeps every tile's (as built), else the tiles' totals
    /// only: what a level's result takes, so that memory follows the queries, not their
    /// tiles (300 queries of 65,536 tiles each had taken the cycle level 1.1 GB where the
    /// functional level takes 17 MB).
    pub fn keep_tile_reports(&mut self, keep: bool) {
        match &mut self.pipe {
            Pipe::O2(machine) => machine.keep_tile_reports(keep),
            Pipe::Ir(machine) => machine.keep_tile_reports(keep),
        }
    }

    /// The depth buffer the machine's depth tests read and write. A machine started
    /// mid-stream may have a pixel's depth set before the pixel's first test
    /// ([`crate::levels::consistent_depths`]); the tests themselves happen as each fragment
    /// is replayed, so a depth set before a fragment is replayed is the one it meets.
    pub fn depth_buffer_mut(&mut self) -> &mut DepthBuffer {
        match &mut self.pipe {
            Pipe::O2(machine) => machine.depth_buffer_mut(),
            Pipe::Ir(machine) => machine.depth_buffer_mut(),
        }
    }

    /// [`Self::finish`], handing the depth buffer's memory back for reuse.
    pub fn finish_recycling(mut self) -> Result<(Report, DepthBuffer), SimError> {
        let state = self.pipe.state()?;
        let (mut report, depth) = match self.pipe {
            Pipe::O2(machine) => machine.finish_recycling()?,
            Pipe::Ir(machine) => machine.finish_recycling()?,
        };
        close_loop(self.front, state, &mut report);
        Ok((report, depth))
    }

    /// Replay one event: the closed loop's records drive the host and the geometry stage;
    /// every event then reaches the pipeline, no earlier than the loop releases it.
    #[inline]
    pub fn event(&mut self, event: &Event) -> Result<(), SimError> {
        let index = self.events;
        self.events += 1;
        match event {
            Event::Fragment(_) => {}
            Event::Primitive => self.pipe.release(self.front.primitive_release())?,
            Event::Geometry(batch) => self.front.geometry(batch),
            Event::HostWork(work) => self.front.host_work(work),
            Event::Wait(id) => {
                let (available, words) = self.awaited(*id, index)?;
                self.front.wait(available, words);
            }
            Event::ConditionalBegin(id) => {
                let (available, _) = self.awaited(*id, index)?;
                self.front.hold_pipe(available);
            }
            Event::Swap => {
                let state = self.pipe.state()?;
                self.front.swap(state);
            }
            _ => {
                self.front.command(event);
                self.pipe.release(self.front.command_release())?
            }
        }
        match &mut self.pipe {
            Pipe::O2(machine) => machine.event(event),
            Pipe::Ir(machine) => machine.event(event),
        }
    }

    /// Replay a span of fragments: what its fragments one by one give, fast-forwarded
    /// where the rule of [`crate::effects`] allows it (fragments are no closed-loop records).
    #[inline]
    pub fn span(&mut self, span: Span) -> Result<(), SimError> {
        self.events += span.depths.len() as u64;
        match &mut self.pipe {
            Pipe::O2(machine) => machine.span(span),
            Pipe::Ir(machine) => machine.span(span),
        }
    }

    /// The cycle the next event fed would enter the pipe (where a query's end fed now would
    /// enter it, before the host releases it): the sampled level marks where a window's
    /// measured part begins by it.
    pub fn entry_cycle(&self) -> u64 {
        match &self.pipe {
            Pipe::O2(machine) => machine.entry_cycle(),
            Pipe::Ir(machine) => machine.entry_cycle(),
        }
    }

    /// A machine started mid-stream: its host and geometry stage take up where `front`
    /// (the analytic level's closed loop at the same point of the stream) is, with this
    /// machine's pipe starting at `origin` on `front`'s timeline
    /// ([`ClosedLoop::resume_from`]). Its clock counts from the earlier of `origin` and the
    /// host's clock there (a host ahead of the pipe keeps its lead), and nothing enters its
    /// pipe before `origin` does: the cycle returned, in its own clock. On the
    /// InfiniteReality-like machine board `b`'s Fragment Generator starts `board_leads[b]`
    /// cycles sooner (a board through its work before the others keeps its lead: the end
    /// token holds no board back), and the clock counts from early enough for the lead;
    /// its merge stages take up from `merges` (on `front`'s timeline), where given.
    pub fn resume_front(
        &mut self,
        front: &ClosedLoop,
        origin: u64,
        board_leads: &[u64],
        merges: Option<&MergeState>,
    ) -> Result<u64, SimError> {
        let lead = board_leads.iter().copied().max().unwrap_or(0);
        let base = origin.saturating_sub(lead).min(front.host_now());
        self.front.resume_from(front, base);
        self.resumed.get_or_insert_with(Resumed::default).base = base;
        let start = origin - base;
        match &mut self.pipe {
            Pipe::Ir(machine) => {
                machine.release_boards(start, board_leads);
                if let Some(merges) = merges {
                    machine.take_merges(merges.moved_back(base));
                }
            }
            pipe => pipe.release(start)?,
        }
        Ok(start)
    }

    /// The answer to query `id` (available cycle and record words) on the timeline this
    /// machine's host was taken up from ([`Self::resume_front`]), before a `wait` or
    /// `begin_conditional` on it: a query that ended before the machine started is then
    /// answered there, moved onto the machine's clock (0 where earlier), not at the start.
    /// A machine that saw the query end keeps its own answer.
    pub fn take_answer(&mut self, id: u32, (available, words): (u64, u64)) {
        if let Some(resumed) = &mut self.resumed {
            let available = available.saturating_sub(resumed.base);
            resumed.answers.insert(id, (available, words));
        }
    }

    /// Fragments fast-forwarded so far ([`crate::effects`]).
    pub fn fast_forwarded_fragments(&self) -> u64 {
        match &self.pipe {
            Pipe::O2(machine) => machine.fast_forwarded_fragments(),
            Pipe::Ir(_) => 0,
        }
    }

    fn awaited(&mut self, id: u32, event: u64) -> Result<(u64, u64), SimError> {
        match self.pipe.result_available(id)? {
            Some(answer) => Ok(answer),
            None => match &self.resumed {
                Some(resumed) => Ok(resumed.answers.get(&id).copied().unwrap_or((0, 0))),
                None => Err(SimError::NoResultToWaitFor { event, id }),
            },
        }
    }

    /// End the replay and report.
    pub fn finish(mut self) -> Result<Report, SimError> {
        let state = self.pipe.state()?;
        let mut report = match self.pipe {
            Pipe::O2(machine) => machine.finish()?,
            Pipe::Ir(machine) => machine.finish()?,
        };
        close_loop(self.front, state, &mut report);
        Ok(report)
    }
}

fn close_loop(front: ClosedLoop, state: PipeState, report: &mut Report) {
    let clock_mhz = front.clock_mhz();
    let (frames, end) = front.finish(state);
    report.close_loop(frames, end, clock_mhz);
}

#[cfg(test)]
mod tests {
    use super::*;
    use occsim_traces::HostWork;

    /// A machine started mid-stream waits for a query that ended before its start until the
    /// timeline it took its host up from has the answer available, on its own clock; a query
    /// answered there before the start holds it no longer, though the host still reads its
    /// words; one it has no answer for is answered at the start.
    #[test]
    fn a_resumed_machine_waits_for_the_answers_of_the_timeline_it_took_up() {
        let arch = Arch::builtin("ir4").unwrap();
        let ir = arch.ir().unwrap();
        let (notify, per_word) = (
            ir.result_notify_latency_cycles,
            ir.result_read_cycles_per_word,
        );
        let mut front = closed_loop_of(&arch).unwrap();
        front.host_work(&HostWork {
            nodes: 10,
            ..HostWork::default()
        });
        let base = front.host_now();
        assert!(base > 0);
        let state = RenderState::new(8, 8);
        let mut machine = MachineBuilder::new(&arch)
            .resume_with_depths(&state, DepthBuffer::unset(8, 8))
            .unwrap();
        // The pipe starts 400 cycles after the host's clock: the clock counts from the host's.
        assert_eq!(
            machine.resume_front(&front, base + 400, &[], None).unwrap(),
            400
        );
        assert_eq!(machine.front.host_now(), 0);
        // Query 7 answered 1,000 cycles past the host's clock, 2 words.
        machine.take_answer(7, (base + 1_000, 2));
        machine.event(&Event::Wait(7)).unwrap();
        let after = 1_000 + notify + 2 * per_word;
        assert_eq!(machine.front.host_now(), after);
        // Query 8 answered before the start: no wait, its 3 words read.
        machine.take_answer(8, (base - 1, 3));
        machine.event(&Event::Wait(8)).unwrap();
        assert_eq!(machine.front.host_now(), after + 3 * per_word);
        // Query 9, no answer given: answered at the start, no words.
        machine.event(&Event::Wait(9)).unwrap();
        assert_eq!(machine.front.host_now(), after + 3 * per_word);
    }
}
