//! The functional level: the golden functional model with the stream checks every level
//! shares. The other levels run it beside their timing.

use crate::error::{check_spec, SimError};
use crate::golden_check::{first_difference, GoldenCheck};
use crate::levels::level::{Fidelity, LevelResult, QueryOutcome};
use occsim_traces::golden::FunctionalModel;
use occsim_traces::{Event, Fragment, QueryMode, QueryShape, QueryTotals, Span};

/// The functional model with the stream checks every level shares: fragments inside the
/// viewport, well-formed queries, results equal to the golden results stored in the stream,
/// waits and conditionals naming a query that has ended.
pub struct FunctionalCore {
    pub(crate) functional: FunctionalModel,
    width: u32,
    height: u32,
    events: u64,
    /// The open query (the model's, when it hears of queries: see [`Self::writes_allowed`]).
    open: Option<QueryShape>,
    open_fragments: u64,
    /// Queries that have ended: what a wait or a conditional may name.
    ended: std::collections::HashSet<u32>,
    /// The result of the query that just ended, waiting for the stream's golden result.
    golden: GoldenCheck,
    queries: Vec<QueryOutcome>,
    fragments: u64,
    primitives: u64,
    /// Where query results come from.
    results: ResultSource,
}

/// Where a core's query results come from.
#[derive(Clone, Copy, PartialEq, Eq)]
enum ResultSource {
    /// The functional model, checked against the stream's golden results.
    Computed,
    /// The stream's golden results, taken (a window-index replay sees no fragment); holds
    /// the fragments counted when a query ended, until its golden result arrives.
    Golden { ended_with: Option<u64> },
}

impl FunctionalCore {
    pub fn new(width: u32, height: u32) -> Result<FunctionalCore, SimError> {
        crate::error::check_viewport(width, height)?;
        Ok(FunctionalCore::with_model(
            FunctionalModel::try_new(width, height)?,
            width,
            height,
            ResultSource::Computed,
        ))
    }

    /// A core for a stream without fragments (a window index): fragments are counted by
    /// [`Self::count_fragments`], render state and queries follow the events, and each
    /// query's result is the golden result the stream carries right after its end.
    pub fn trusting_golden(width: u32, height: u32) -> Result<FunctionalCore, SimError> {
        crate::error::check_viewport(width, height)?;
        // No fragment reaches the model: it keeps the render state and the open query, and
        // a one-pixel depth buffer spares allocating and filling the viewport's.
        Ok(FunctionalCore::with_model(
            FunctionalModel::new(1, 1),
            width,
            height,
            ResultSource::Golden { ended_with: None },
        ))
    }

    fn with_model(
        functional: FunctionalModel,
        width: u32,
        height: u32,
        results: ResultSource,
    ) -> FunctionalCore {
        FunctionalCore {
            functional,
            width,
            height,
            events: 0,
            open: None,
            open_fragments: 0,
            ended: std::collections::HashSet::new(),
            golden: GoldenCheck::default(),
            queries: Vec::new(),
            fragments: 0,
            primitives: 0,
            results,
        }
    }

    /// `count` fragments passed, whose effects on the depth buffer the caller does not need.
    pub(crate) fn count_fragments(&mut self, count: u64) {
        debug_assert!(self.results != ResultSource::Computed);
        self.events += count;
        self.fragments += count;
        self.open_fragments += count;
    }

    /// Reject a fragment outside the viewport (the next event's index).
    #[inline]
    pub(crate) fn check_fragment(&self, fragment: &Fragment) -> Result<(), SimError> {
        self.check_fragment_at(fragment, self.events)
    }

    /// Reject a fragment outside the viewport, `event` its index in the stream.
    #[inline]
    fn check_fragment_at(&self, fragment: &Fragment, event: u64) -> Result<(), SimError> {
        crate::error::check_fragment_inside(fragment, event, self.width, self.height)
    }

    /// Apply a fragment already checked by [`Self::check_fragment`].
    #[inline]
    pub(crate) fn apply_fragment(&mut self, fragment: Fragment) {
        self.events += 1;
        self.fragments += 1;
        self.open_fragments += 1;
        self.functional.fragment(fragment);
    }

    /// Reject a span with a fragment outside the viewport (naming the first such).
    #[inline]
    pub(crate) fn check_span(&self, span: Span) -> Result<(), SimError> {
        let end = span.x as u32 + span.depths.len() as u32;
        if (span.y as u32) < self.height && end <= self.width {
            return Ok(());
        }
        span.fragments()
            .zip(self.events..)
            .try_for_each(|(fragment, event)| self.check_fragment_at(&fragment, event))
    }

    /// Apply a span already checked by [`Self::check_span`].
    #[inline]
    pub(crate) fn apply_span(&mut self, span: Span) {
        let len = span.depths.len() as u64;
        self.events += len;
        self.fragments += len;
        self.open_fragments += len;
        self.functional.span(span);
    }

    /// A span of fragments at once: the same as its fragments one by one.
    #[inline]
    pub fn span(&mut self, span: Span) -> Result<(), SimError> {
        self.check_span(span)?;
        self.apply_span(span);
        Ok(())
    }

    /// The index in the stream of the next event it takes (for errors that name it).
    pub fn next_event(&self) -> u64 {
        self.events
    }

    /// Apply one event; returns the totals of a query that ended with it: the stream's
    /// golden result's when the core trusts them.
    pub fn event(&mut self, event: &Event) -> Result<Option<QueryTotals>, SimError> {
        let index = self.events;
        let trusting = self.results != ResultSource::Computed;
        match event {
            Event::Fragment(fragment) => {
                self.check_fragment(fragment)?;
                self.apply_fragment(*fragment);
                return Ok(None);
            }
            Event::Primitive => {
                self.primitive();
                return Ok(None);
            }
            // No fragment reaches a trusting core's model: the golden result stands for its
            // counts, so the model need not hear of the query (opening one sets up a
            // counter a tile, and closing it builds a result: a window index's queries hold
            // hundreds of tiles, and the lazy-grid walk's analytic replay spent 4% on them).
            Event::QueryBegin(spec) if trusting => {
                self.begin_trusted(spec.shape())?;
                return Ok(None);
            }
            Event::QueryBegin(spec) => self.open_query(spec.shape(), index)?,
            Event::QueryEnd => {
                let open = self
                    .open
                    .take()
                    .ok_or(SimError::EndWithoutBegin { event: index })?;
                self.ended.insert(open.id);
                if let ResultSource::Golden { ended_with } = &mut self.results {
                    self.events += 1;
                    if ended_with.replace(self.open_fragments).is_some() {
                        return Err(SimError::MissingGolden);
                    }
                    return Ok(None);
                }
            }
            Event::Wait(id) | Event::ConditionalBegin(id) if !self.ended.contains(id) => {
                return Err(SimError::NoResultToWaitFor {
                    event: index,
                    id: *id,
                });
            }
            Event::QueryResult(golden) if trusting => {
                return self.result_trusted(&golden.totals()).map(Some);
            }
            Event::QueryResult(golden) => {
                self.events += 1;
                self.golden.check(golden, index, |simulated, golden| {
                    first_difference(simulated, golden, u64::MAX)
                })?;
                return Ok(None);
            }
            _ => {}
        }
        self.events += 1;
        let Some(result) = self.functional.event(event) else {
            return Ok(None);
        };
        let totals = result.totals();
        self.queries
            .push(QueryOutcome::of(&totals, self.open_fragments));
        self.golden.expect(self.queries.len() - 1, result);
        Ok(Some(totals))
    }

    /// A primitive: nothing the functional model keeps changes, so it is counted, and done.
    #[inline]
    pub(crate) fn primitive(&mut self) {
        self.primitives += 1;
        self.events += 1;
    }

    /// Whether a passing fragment may write depth and colour now: no occlusion-render-mode
    /// query (brief, verbose) is open. What the model says when it hears of the queries
    /// (the same query is open in both), and what a trusting core's model cannot.
    pub(crate) fn writes_allowed(&self) -> bool {
        !self
            .open
            .is_some_and(|open| open.mode.is_occlusion_render_mode())
    }

    /// A query begins (`event` its index): checked, and open.
    fn open_query(&mut self, shape: QueryShape, event: u64) -> Result<(), SimError> {
        check_spec(shape, event, self.open.map(|open| open.id))?;
        self.open = Some(shape);
        self.open_fragments = 0;
        Ok(())
    }

    /// A query begin to a core that trusts the golden results: its model hears nothing of
    /// it, so its shape is all it takes (as a window index read skimmed gives it,
    /// [`occsim_traces::trace::IndexItem::Shape`]).
    pub(crate) fn begin_trusted(&mut self, shape: QueryShape) -> Result<(), SimError> {
        self.open_query(shape, self.events)?;
        self.events += 1;
        Ok(())
    }

    /// A golden result's totals to a core that trusts them (as a window index read skimmed
    /// gives them, [`occsim_traces::trace::IndexItem::Totals`]): the totals of the query
    /// that ended before.
    pub(crate) fn result_trusted(&mut self, totals: &QueryTotals) -> Result<QueryTotals, SimError> {
        let index = self.events;
        self.events += 1;
        let ResultSource::Golden {
            ended_with: Some(fragments),
        } = self.results
        else {
            return Err(SimError::ResultWithoutQuery {
                event: index,
                id: totals.id,
            });
        };
        self.results = ResultSource::Golden { ended_with: None };
        self.queries.push(QueryOutcome::of(totals, fragments));
        Ok(*totals)
    }

    /// The mode of the `index`-th query that ended.
    pub(crate) fn query_mode(&self, index: usize) -> QueryMode {
        self.queries[index].mode
    }

    /// The result without timing (the functional level's answer).
    pub fn finish(self) -> Result<LevelResult, SimError> {
        if let Some(open) = self.open {
            return Err(SimError::OpenAtEnd { id: open.id });
        }
        if let ResultSource::Golden {
            ended_with: Some(_),
        } = self.results
        {
            return Err(SimError::MissingGolden);
        }
        Ok(LevelResult {
            level: Fidelity::Functional,
            machine: String::new(),
            arch: Vec::new(),
            viewport_width: self.width,
            viewport_height: self.height,
            fragments: self.fragments,
            primitives: self.primitives,
            checked_queries: self.golden.checked(),
            total_cycles: None,
            latency_mean_cycles: None,
            latency_p50_cycles: None,
            latency_p95_cycles: None,
            latency_max_cycles: None,
            effects: None,
            fast_forwarded_fragments: None,
            sampled_windows: None,
            from_window_index: self.results != ResultSource::Computed,
            older_index: None,
            queries: self.queries,
            frame_cycles: Vec::new(),
            frames_per_second: None,
            report: None,
        })
    }
}
