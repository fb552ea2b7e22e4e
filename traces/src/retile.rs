//! `--retile GxH`: a pure event transformer that replaces every brief-mode query's tiles by a
//! G by H grid over the viewport, so tile counts can be swept on one trace.
//!
//! The golden results in the stream answer the old tiles, so they are dropped and the
//! functional golden model ([`FunctionalModel`]) recomputes every query's result, emitted
//! after its `QueryEnd` as a trace stores it. Other queries (samples, any, verbose) keep
//! their tiles; their recomputed results equal the stored ones.

use crate::event::{Event, Span};
use crate::golden::{EventSink, FunctionalModel};
use crate::query::{QueryMode, Tile, MAX_TILES};
use std::str::FromStr;
use thiserror::Error;

#[derive(Debug, Error, PartialEq, Eq)]
pub enum RetileError {
    #[error("tile grid '{0}': expected GxH with G and H positive integers, e.g. 4x4")]
    Syntax(String),
    #[error("tile grid {columns}x{rows} does not fit the {width}x{height} viewport: at most one tile per pixel column and row")]
    TooFine {
        columns: u32,
        rows: u32,
        width: u32,
        height: u32,
    },
    #[error("tile grid {columns}x{rows} has more than {max} tiles")]
    TooMany { columns: u32, rows: u32, max: usize },
    #[error(transparent)]
    ViewportBuffer(#[from] crate::golden::ViewportBufferTooLarge),
}

/// A grid of `columns` x `rows` tiles covering the viewport.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileGrid {
    pub columns: u32,
    pub rows: u32,
}

impl FromStr for TileGrid {
    type Err = RetileError;

    fn from_str(text: &str) -> Result<TileGrid, RetileError> {
        let syntax = || RetileError::Syntax(text.to_string());
        let (columns, rows) = text.trim().split_once(['x', 'X']).ok_or_else(syntax)?;
        let parse = |s: &str| s.trim().parse::<u32>().ok().filter(|&n| n > 0);
        let grid = TileGrid {
            columns: parse(columns).ok_or_else(syntax)?,
            rows: parse(rows).ok_or_else(syntax)?,
        };
        // Refused as the flag is read: found at the first query, after the replay's machine
        // was made, a grid of too many tiles over a large viewport had taken 1 GB first.
        grid.count_checked()
    }
}

impl std::fmt::Display for TileGrid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.columns, self.rows)
    }
}

impl TileGrid {
    /// The grid, if it has at most [`MAX_TILES`] tiles (what one query holds).
    fn count_checked(self) -> Result<TileGrid, RetileError> {
        match self.columns as u64 * self.rows as u64 > MAX_TILES as u64 {
            true => Err(RetileError::TooMany {
                columns: self.columns,
                rows: self.rows,
                max: MAX_TILES,
            }),
            false => Ok(self),
        }
    }

    /// The tiles, row by row from the bottom: tile `(c, r)` spans x in
    /// `c*W/G .. (c+1)*W/G` and y in `r*H'/H .. (r+1)*H'/H` (integer division, so the grid
    /// covers the viewport exactly and no tile is empty).
    pub fn tiles(&self, width: u32, height: u32) -> Result<Vec<Tile>, RetileError> {
        let (columns, rows) = (self.columns, self.rows);
        if columns > width || rows > height {
            return Err(RetileError::TooFine {
                columns,
                rows,
                width,
                height,
            });
        }
        self.count_checked()?;
        let edge = |i: u32, n: u32, side: u32| (i as u64 * side as u64 / n as u64) as u32;
        Ok((0..rows)
            .flat_map(|r| {
                (0..columns).map(move |c| {
                    let (x0, x1) = (edge(c, columns, width), edge(c + 1, columns, width));
                    let (y0, y1) = (edge(r, rows, height), edge(r + 1, rows, height));
                    Tile::new(x0, y0, x1 - x0, y1 - y0)
                })
            })
            .collect())
    }
}

/// An [`EventSink`] adapter: rewrites brief queries' tiles and the golden results, then
/// passes every event on to `inner`.
pub struct Retile<S: EventSink> {
    tiles: Vec<Tile>,
    golden: FunctionalModel,
    inner: S,
}

impl<S: EventSink> Retile<S> {
    /// Retile a `width` x `height` trace's events into `inner`.
    pub fn new(
        grid: TileGrid,
        width: u32,
        height: u32,
        inner: S,
    ) -> Result<Retile<S>, RetileError> {
        Ok(Retile {
            tiles: grid.tiles(width, height)?,
            golden: FunctionalModel::try_new(width, height)?,
            inner,
        })
    }

    pub fn inner(&self) -> &S {
        &self.inner
    }

    pub fn inner_mut(&mut self) -> &mut S {
        &mut self.inner
    }

    pub fn into_inner(self) -> S {
        self.inner
    }
}

impl<S: EventSink> EventSink for Retile<S> {
    type Error = S::Error;
    #[inline]
    fn event(&mut self, event: &Event) -> Result<(), S::Error> {
        match event {
            Event::QueryResult(_) => Ok(()),
            Event::QueryBegin(spec) if spec.mode == QueryMode::Brief => {
                let mut spec = spec.clone();
                spec.tiles.clone_from(&self.tiles);
                let event = Event::QueryBegin(spec);
                self.golden.event(&event);
                self.inner.event(&event)
            }
            Event::Fragment(fragment) => {
                self.golden.fragment(*fragment);
                self.inner.event(event)
            }
            _ => {
                let result = self.golden.event(event);
                self.inner.event(event)?;
                match result {
                    Some(result) => self.inner.event(&Event::QueryResult(result)),
                    None => Ok(()),
                }
            }
        }
    }

    /// A span whole, to the functional model and on to `inner` (a trace reader's spans lie
    /// in the viewport). Passed on as its fragments one by one, as the default does, a
    /// retiled replay took every fragment one by one, and the O2's cycle model, which
    /// fast-forwards whole spans, fast-forwarded none.
    #[inline]
    fn span(&mut self, span: Span) -> Result<(), S::Error> {
        self.golden.span(span);
        self.inner.span(span)
    }
}

/// `events` of a `width` x `height` trace, retiled to `grid`.
pub fn retile_events(
    events: &[Event],
    grid: TileGrid,
    width: u32,
    height: u32,
) -> Result<Vec<Event>, RetileError> {
    let mut retile = Retile::new(grid, width, height, Vec::with_capacity(events.len()))?;
    for event in events {
        retile.event(event);
    }
    Ok(retile.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::query::QuerySpec;
    use crate::{Fragment, Rect};

    #[test]
    fn grids_parse_and_cover_the_viewport() {
        assert_eq!(
            "3x2".parse(),
            Ok(TileGrid {
                columns: 3,
                rows: 2
            })
        );
        assert!("3".parse::<TileGrid>().is_err());
        assert!("0x2".parse::<TileGrid>().is_err());
        assert!("ax2".parse::<TileGrid>().is_err());
        // Too many tiles for one query (65,536) is refused as the flag is read, before any
        // viewport is known; 256x256 is the most.
        assert_eq!(
            "1024x1024".parse::<TileGrid>(),
            Err(RetileError::TooMany {
                columns: 1024,
                rows: 1024,
                max: 65_536
            })
        );
        assert!("256x256".parse::<TileGrid>().is_ok());
        let tiles = TileGrid {
            columns: 3,
            rows: 2,
        }
        .tiles(10, 5)
        .unwrap();
        assert_eq!(
            tiles,
            [
                Rect::new(0, 0, 3, 2),
                Rect::new(3, 0, 3, 2),
                Rect::new(6, 0, 4, 2),
                Rect::new(0, 2, 3, 3),
                Rect::new(3, 2, 3, 3),
                Rect::new(6, 2, 4, 3),
            ]
        );
        assert!(TileGrid {
            columns: 11,
            rows: 1
        }
        .tiles(10, 5)
        .is_err());
    }

    #[test]
    fn brief_queries_get_the_grid_and_fresh_results() {
        let spec = QuerySpec {
            id: 4,
            mode: QueryMode::Brief,
            buffer_entries: 8,
            tiles: vec![Rect::new(0, 0, 4, 2)],
        };
        let fragment = |x| Event::Fragment(Fragment { x, y: 1, z: 3 });
        let events = [
            Event::QueryBegin(spec),
            fragment(0),
            fragment(3),
            fragment(3),
            Event::QueryEnd,
            Event::QueryResult(crate::QueryResult {
                id: 4,
                mode: QueryMode::Brief,
                tiles: vec![],
                overflowed_buffers: 0,
            }),
        ];
        let out = retile_events(
            &events,
            TileGrid {
                columns: 2,
                rows: 1,
            },
            4,
            2,
        )
        .unwrap();
        assert_eq!(out.len(), events.len());
        let Event::QueryBegin(spec) = &out[0] else {
            panic!()
        };
        assert_eq!(spec.tiles, [Rect::new(0, 0, 2, 2), Rect::new(2, 0, 2, 2)]);
        let Event::QueryResult(result) = &out[5] else {
            panic!()
        };
        // Hand-worked: tile 0 holds x = 0; tile 1 holds x = 3 twice, and both pass: brief
        // queries never write depth.
        assert_eq!((result.tiles[0].nohc, result.tiles[0].phc), (1, 1));
        assert_eq!((result.tiles[1].nohc, result.tiles[1].phc), (2, 2));
    }

    /// A sink that keeps what reached it whole: the spans' lengths, and the other events.
    #[derive(Default)]
    struct Spans {
        spans: Vec<usize>,
        events: Vec<Event>,
    }

    impl EventSink for Spans {
        type Error = std::convert::Infallible;
        fn event(&mut self, event: &Event) -> Result<(), Self::Error> {
            self.events.push(event.clone());
            Ok(())
        }
        fn span(&mut self, span: Span) -> Result<(), Self::Error> {
            self.spans.push(span.depths.len());
            Ok(())
        }
    }

    #[test]
    fn a_span_passes_on_whole_and_counts_as_its_fragments() {
        let spec = QuerySpec {
            id: 1,
            mode: QueryMode::Brief,
            buffer_entries: 8,
            tiles: vec![Rect::new(0, 0, 4, 2)],
        };
        let grid = TileGrid {
            columns: 2,
            rows: 1,
        };
        let mut retile = Retile::new(grid, 4, 2, Spans::default()).unwrap();
        retile.event(&Event::QueryBegin(spec)).unwrap();
        // Pixels 1..4 of row 0: one in tile 0 (x < 2), two in tile 1.
        let depths = [5, 6, 7];
        retile
            .span(Span {
                x: 1,
                y: 0,
                depths: &depths,
            })
            .unwrap();
        retile.event(&Event::QueryEnd).unwrap();
        let sink = retile.into_inner();
        // Whole, so that a machine behind may take it in bulk (the O2 fast-forwards spans).
        assert_eq!(sink.spans, [3]);
        let Some(Event::QueryResult(result)) = sink.events.last() else {
            panic!("a result after the end: {:?}", sink.events)
        };
        // Hand-worked: the depth test passes on the cleared buffer, brief queries draw
        // nothing: tile 0 counts x = 1 (1 of 1), tile 1 counts x = 2 and 3 (2 of 2).
        assert_eq!((result.tiles[0].nohc, result.tiles[0].phc), (1, 1));
        assert_eq!((result.tiles[1].nohc, result.tiles[1].phc), (2, 2));
    }
}
