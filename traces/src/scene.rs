//! The scene language: one OpenGL-like command a line, `#` starts a comment.
//!
//! ```text
//! viewport W H
//! clear
//! depth_func never|less|equal|lequal|greater|notequal|gequal|always
//! depth_mask 0|1
//! depth_test 0|1
//! cull 0|1
//! scissor X Y W H | scissor off
//! begin ID [samples|any|brief|verbose] [buffer=N] [tile=X,Y,W,H]...
//! end
//! tri x y z w  x y z w  x y z w
//! end_draw
//! wait ID
//! begin_conditional ID
//! end_conditional
//! host [nodes=N] [boxes=N] [decisions=N] [pixels=N]
//! swap
//! ```
//! `viewport` comes first and once. Queries do not nest. Coordinates are clip coordinates,
//! parsed as 32-bit floats; NaN and infinities are rejected.
//!
//! The closed loop's commands mirror the GL calls an application makes: `wait ID` reads
//! query ID's result, blocking the host (`glGetQueryObject(GL_QUERY_RESULT)`);
//! `begin_conditional ID` ... `end_conditional` is `glBeginConditionalRender(ID,
//! GL_QUERY_WAIT)`: the draws between are discarded when query ID passed no fragment (for
//! brief and verbose queries: when no tile's NOHC is above zero); `host` is the traversal's
//! work before the next command (nodes visited, boxes tested, decisions taken, framebuffer
//! pixels read back and searched); `swap` ends
//! a frame. `wait` and `begin_conditional` name a query that has ended; conditionals do not
//! nest.
//!
//! Consecutive `tri` lines are one draw (one `glDrawArrays`); any other command ends it.
//! `end_draw` ends it and does nothing else: two objects drawn one after the other with no
//! state change between are two draws, as an application's two draw calls.

use crate::event::HostWork;
use crate::query::{
    QueryMode, QuerySpec, Tile, BRIEF_RECORD_ENTRIES, DEFAULT_BRIEF_BUFFER, DEFAULT_VERBOSE_BUFFER,
    MAX_BUFFER_ENTRIES, MAX_TILES,
};
use crate::state::{DepthFunc, Rect, MAX_VIEWPORT_SIDE};
use crate::words::counted;
use std::collections::BTreeSet;
use std::io::BufRead;

/// A scene command, one per line.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    Viewport {
        width: u32,
        height: u32,
    },
    Clear,
    DepthFunc(DepthFunc),
    DepthMask(bool),
    DepthTest(bool),
    Cull(bool),
    Scissor(Option<Rect>),
    Begin(QuerySpec),
    End,
    /// A triangle's three vertices in clip coordinates (x, y, z, w).
    Tri([[f32; 4]; 3]),
    /// The end of a draw, and nothing else.
    EndDraw,
    /// The host blocks until query ID's result is available.
    Wait(u32),
    /// `glBeginConditionalRender(ID, GL_QUERY_WAIT)`.
    BeginConditional(u32),
    EndConditional,
    /// The host's traversal work before the next command.
    Host(HostWork),
    /// The frame ends.
    Swap,
}

/// A command and the line it came from (1-based).
#[derive(Clone, Debug, PartialEq)]
pub struct SceneLine {
    pub line: u32,
    pub command: Command,
}

/// A scene that cannot be read, with the place it went wrong.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{file}:{line}: {message}")]
    Syntax {
        file: String,
        line: u32,
        message: String,
    },
    /// The I/O error's words in the message, not also as its source (printed whole, the
    /// chain would say them twice).
    #[error("{file}: {io}")]
    Io { file: String, io: std::io::Error },
    /// No command at all (an empty file, or comments alone): no line to name.
    #[error("{file}: empty scene: expected `viewport W H` first")]
    Empty { file: String },
}

/// Longest scene line accepted, in bytes: no command needs more than a few hundred, and a
/// bound keeps a hostile file from growing one line without limit.
const MAX_LINE_BYTES: usize = 1 << 20;

/// Streams commands out of a scene text, checking each line as it comes.
pub struct SceneReader<R> {
    input: R,
    file: String,
    line_number: u32,
    buffer: Vec<u8>,
    viewport: Option<(u32, u32)>,
    open_query: Option<u32>,
    /// Queries that have ended at least once (what `wait` and `begin_conditional` may name).
    ended_queries: BTreeSet<u32>,
    open_conditional: Option<u32>,
    finished: bool,
}

impl<R: BufRead> SceneReader<R> {
    /// `file` names the input in error messages.
    pub fn new(input: R, file: impl Into<String>) -> SceneReader<R> {
        SceneReader {
            input,
            file: file.into(),
            line_number: 0,
            buffer: Vec::new(),
            viewport: None,
            open_query: None,
            ended_queries: BTreeSet::new(),
            open_conditional: None,
            finished: false,
        }
    }

    fn error(&self, message: impl Into<String>) -> SceneError {
        SceneError::Syntax {
            file: self.file.clone(),
            line: self.line_number,
            message: message.into(),
        }
    }

    /// Read one raw line into `self.buffer`; false at end of input.
    fn read_line(&mut self) -> Result<bool, SceneError> {
        self.buffer.clear();
        let mut limited = std::io::Read::take(&mut self.input, MAX_LINE_BYTES as u64 + 1);
        let n = limited
            .read_until(b'\n', &mut self.buffer)
            .map_err(|io| SceneError::Io {
                file: self.file.clone(),
                io,
            })?;
        if n == 0 {
            return Ok(false);
        }
        self.line_number += 1;
        if self.buffer.len() > MAX_LINE_BYTES {
            return Err(self.error(format!("line longer than {MAX_LINE_BYTES} bytes")));
        }
        Ok(true)
    }

    fn next_command(&mut self) -> Result<Option<SceneLine>, SceneError> {
        while self.read_line()? {
            let text = std::str::from_utf8(&self.buffer)
                .map_err(|_| self.error("line is not valid UTF-8"))?;
            // A byte order mark (Windows Notepad writes one) is no part of the first command.
            let text = match self.line_number {
                1 => text.strip_prefix('\u{feff}').unwrap_or(text),
                _ => text,
            };
            let text = text.split('#').next().unwrap_or("").trim().to_owned();
            if text.is_empty() {
                continue;
            }
            let command = self.parse_command(&text)?;
            return Ok(Some(SceneLine {
                line: self.line_number,
                command,
            }));
        }
        if let Some(id) = self.open_query {
            return Err(self.error(format!("end of scene inside query {id}: expected `end`")));
        }
        if let Some(id) = self.open_conditional {
            return Err(self.error(format!(
                "end of scene inside `begin_conditional {id}`: expected `end_conditional`"
            )));
        }
        if self.viewport.is_none() {
            // Any command but `viewport` first is refused on its line: none came.
            return Err(SceneError::Empty {
                file: self.file.clone(),
            });
        }
        Ok(None)
    }

    fn parse_command(&mut self, text: &str) -> Result<Command, SceneError> {
        let mut words = text.split_whitespace();
        let keyword = words.next().unwrap_or("");
        let args: Vec<&str> = words.collect();
        if keyword.starts_with("OCCT") && self.viewport.is_none() {
            // A trace's magic number (`OCCT\r\n...`) where a scene's first line goes.
            return Err(self.error(
                "an occsim trace, not a scene: `replay`, `trace info` and `trace dump` read traces; `count` and `trace gen` read scenes".to_string(),
            ));
        }
        if keyword != "viewport" && self.viewport.is_none() {
            return Err(self.error(format!(
                "`{keyword}` before `viewport`: a scene starts with `viewport W H`"
            )));
        }
        let command = match keyword {
            "viewport" => self.parse_viewport(&args)?,
            "end_draw" => {
                self.expect_args(keyword, &args, 0, "end_draw")?;
                Command::EndDraw
            }
            "clear" => {
                self.expect_args(keyword, &args, 0, "clear")?;
                Command::Clear
            }
            "depth_func" => {
                self.expect_args(keyword, &args, 1, "depth_func never|less|equal|lequal|greater|notequal|gequal|always")?;
                Command::DepthFunc(DepthFunc::from_name(args[0]).ok_or_else(|| {
                    self.error(format!(
                        "unknown depth function `{}`: expected never, less, equal, lequal, greater, notequal, gequal or always",
                        args[0]
                    ))
                })?)
            }
            "depth_mask" => Command::DepthMask(self.parse_flag(keyword, &args)?),
            "depth_test" => Command::DepthTest(self.parse_flag(keyword, &args)?),
            "cull" => Command::Cull(self.parse_flag(keyword, &args)?),
            "scissor" => self.parse_scissor(&args)?,
            "begin" => self.parse_begin(&args)?,
            "end" => {
                self.expect_args(keyword, &args, 0, "end")?;
                let Some(id) = self.open_query.take() else {
                    return Err(self.error("`end` without an open query"));
                };
                self.ended_queries.insert(id);
                Command::End
            }
            "tri" => self.parse_tri(&args)?,
            "wait" => Command::Wait(self.parse_ended_query(keyword, &args)?),
            "begin_conditional" => {
                if let Some(open) = self.open_conditional {
                    return Err(self.error(format!(
                        "`begin_conditional` inside `begin_conditional {open}`: conditionals do not nest, expected `end_conditional` first"
                    )));
                }
                let id = self.parse_ended_query(keyword, &args)?;
                self.open_conditional = Some(id);
                Command::BeginConditional(id)
            }
            "end_conditional" => {
                self.expect_args(keyword, &args, 0, "end_conditional")?;
                if self.open_conditional.take().is_none() {
                    return Err(self.error("`end_conditional` without `begin_conditional`"));
                }
                Command::EndConditional
            }
            "host" => self.parse_host(&args)?,
            "swap" => {
                self.expect_args(keyword, &args, 0, "swap")?;
                Command::Swap
            }
            other => {
                return Err(self.error(format!(
                    "unknown command `{other}`: expected viewport, clear, depth_func, depth_mask, depth_test, cull, scissor, begin, end, tri, end_draw, wait, begin_conditional, end_conditional, host or swap"
                )))
            }
        };
        Ok(command)
    }

    fn expect_args(
        &self,
        keyword: &str,
        args: &[&str],
        count: usize,
        usage: &str,
    ) -> Result<(), SceneError> {
        if args.len() != count {
            return Err(self.error(format!(
                "`{keyword}` takes {}, found {}: expected `{usage}`",
                counted(count as u64, "argument", "arguments"),
                args.len()
            )));
        }
        Ok(())
    }

    fn parse_u32(&self, what: &str, word: &str) -> Result<u32, SceneError> {
        word.parse::<u32>().map_err(|_| {
            self.error(format!(
                "{what}: expected a whole number from 0 to {}, found `{word}`",
                u32::MAX
            ))
        })
    }

    fn buffer_out_of_range(&self, written: &str) -> SceneError {
        self.error(format!(
            "buffer={written} out of range: expected {BRIEF_RECORD_ENTRIES} (the brief record) to {MAX_BUFFER_ENTRIES} entries"
        ))
    }

    /// A whole number as written, however large (past `u64`, `u64::MAX`), for a caller that
    /// checks its own range and says it: "expected a whole number from 0 to 4294967295"
    /// had answered a viewport side of 99999999999, whose range is 1 to 16384.
    fn parse_whole(&self, what: &str, word: &str) -> Result<u64, SceneError> {
        // As `u32`'s parse reads the scene's other numbers: a `+` may lead.
        let digits = word.strip_prefix('+').unwrap_or(word);
        if !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) {
            return Ok(digits.parse::<u64>().unwrap_or(u64::MAX));
        }
        Err(self.error(format!("{what}: expected a whole number, found `{word}`")))
    }

    fn parse_flag(&self, keyword: &str, args: &[&str]) -> Result<bool, SceneError> {
        self.expect_args(keyword, args, 1, &format!("{keyword} 0|1"))?;
        match args[0] {
            "0" => Ok(false),
            "1" => Ok(true),
            other => Err(self.error(format!("`{keyword}` takes 0 or 1, found `{other}`"))),
        }
    }

    fn parse_viewport(&mut self, args: &[&str]) -> Result<Command, SceneError> {
        if self.viewport.is_some() {
            return Err(self.error("second `viewport`: a scene has one viewport, given first"));
        }
        self.expect_args("viewport", args, 2, "viewport W H")?;
        let mut sides = [0u32; 2];
        for ((name, word), side) in ["width", "height"].into_iter().zip(args).zip(&mut sides) {
            let whole = self.parse_whole(&format!("viewport {name}"), word)?;
            *side = match u32::try_from(whole) {
                Ok(whole) if (1..=MAX_VIEWPORT_SIDE).contains(&whole) => whole,
                _ => {
                    return Err(self.error(format!(
                        "viewport {name} {word} out of range: expected 1 to {MAX_VIEWPORT_SIDE}"
                    )))
                }
            };
        }
        let [width, height] = sides;
        self.viewport = Some((width, height));
        Ok(Command::Viewport { width, height })
    }

    fn parse_scissor(&self, args: &[&str]) -> Result<Command, SceneError> {
        if args == ["off"] {
            return Ok(Command::Scissor(None));
        }
        self.expect_args("scissor", args, 4, "scissor X Y W H | scissor off")?;
        let v: Vec<u32> = args
            .iter()
            .zip(["scissor x", "scissor y", "scissor width", "scissor height"])
            .map(|(a, what)| self.parse_u32(what, a))
            .collect::<Result<_, _>>()?;
        Ok(Command::Scissor(Some(Rect::new(v[0], v[1], v[2], v[3]))))
    }

    fn parse_begin(&mut self, args: &[&str]) -> Result<Command, SceneError> {
        let usage = "begin ID [samples|any|brief|verbose] [buffer=N] [tile=X,Y,W,H]...";
        if let Some(open) = self.open_query {
            return Err(self.error(format!(
                "`begin` inside query {open}: queries do not nest, expected `end` first"
            )));
        }
        let Some((id_word, rest)) = args.split_first() else {
            return Err(self.error(format!("`begin` needs a query id: expected `{usage}`")));
        };
        let id = self.parse_u32("query id", id_word)?;
        let mut mode = None;
        let mut buffer = None;
        let mut tiles = Vec::new();
        for word in rest {
            if let Some(value) = word.strip_prefix("buffer=") {
                if buffer.is_some() {
                    return Err(self.error("`buffer=` given twice"));
                }
                let whole = self.parse_whole("buffer size", value)?;
                match u32::try_from(whole) {
                    Ok(entries) => buffer = Some(entries),
                    Err(_) => return Err(self.buffer_out_of_range(value)),
                }
            } else if let Some(value) = word.strip_prefix("tile=") {
                if tiles.len() == MAX_TILES {
                    return Err(self.error(format!("more than {MAX_TILES} tiles in one query")));
                }
                tiles.push(self.parse_tile(value)?);
            } else if let Some(m) = QueryMode::from_name(word) {
                if mode.is_some() {
                    return Err(self.error("query mode given twice"));
                }
                mode = Some(m);
            } else {
                return Err(self.error(format!(
                    "unexpected `{word}` in `begin`: expected `{usage}`"
                )));
            }
        }
        let mode = mode.unwrap_or(QueryMode::Samples);
        let (width, height) = self.viewport.unwrap_or((0, 0));
        if !mode.is_occlusion_render_mode() && (buffer.is_some() || !tiles.is_empty()) {
            return Err(self.error(format!(
                "`{}` queries take no tiles or buffer: those belong to brief and verbose",
                mode.name()
            )));
        }
        let buffer_entries = buffer.unwrap_or(match mode {
            QueryMode::Verbose => DEFAULT_VERBOSE_BUFFER,
            _ => DEFAULT_BRIEF_BUFFER,
        });
        if !(BRIEF_RECORD_ENTRIES..=MAX_BUFFER_ENTRIES).contains(&buffer_entries) {
            return Err(self.buffer_out_of_range(&buffer_entries.to_string()));
        }
        for tile in &tiles {
            if tile.x as u64 + tile.width as u64 > width as u64
                || tile.y as u64 + tile.height as u64 > height as u64
            {
                return Err(self.error(format!(
                    "tile={},{},{},{} reaches outside the {width}x{height} viewport",
                    tile.x, tile.y, tile.width, tile.height
                )));
            }
        }
        if tiles.is_empty() {
            tiles.push(Rect::new(0, 0, width, height));
        }
        self.open_query = Some(id);
        Ok(Command::Begin(QuerySpec {
            id,
            mode,
            buffer_entries,
            tiles,
        }))
    }

    fn parse_tile(&self, value: &str) -> Result<Tile, SceneError> {
        let parts: Vec<&str> = value.split(',').collect();
        if parts.len() != 4 {
            return Err(self.error(format!("tile=`{value}`: expected four numbers X,Y,W,H")));
        }
        let v: Vec<u32> = parts
            .iter()
            .map(|p| self.parse_u32("tile coordinate", p))
            .collect::<Result<_, _>>()?;
        if v[2] == 0 || v[3] == 0 {
            return Err(self.error(format!(
                "tile={value} is empty: width and height must be at least 1"
            )));
        }
        Ok(Rect::new(v[0], v[1], v[2], v[3]))
    }

    /// `wait ID` and `begin_conditional ID`: ID must name a query that has ended, or there
    /// is no result to wait for (a GL program would block forever or get an error).
    fn parse_ended_query(&self, keyword: &str, args: &[&str]) -> Result<u32, SceneError> {
        self.expect_args(keyword, args, 1, &format!("{keyword} ID"))?;
        let id = self.parse_u32("query id", args[0])?;
        if !self.ended_queries.contains(&id) {
            let why = if self.open_query == Some(id) {
                "is still open (`end` it first)"
            } else {
                "has not been begun and ended above"
            };
            return Err(self.error(format!(
                "`{keyword} {id}`: query {id} {why}, so it has no result"
            )));
        }
        Ok(id)
    }

    fn parse_host(&self, args: &[&str]) -> Result<Command, SceneError> {
        let usage = "host [nodes=N] [boxes=N] [decisions=N] [pixels=N]";
        if args.is_empty() {
            return Err(self.error(format!(
                "`host` needs at least one count: expected `{usage}`"
            )));
        }
        let mut work = HostWork::default();
        let mut seen = Vec::new();
        for word in args {
            let Some((key, value)) = word.split_once('=') else {
                return Err(
                    self.error(format!("unexpected `{word}` in `host`: expected `{usage}`"))
                );
            };
            let slot = match key {
                "nodes" => &mut work.nodes,
                "boxes" => &mut work.boxes,
                "decisions" => &mut work.decisions,
                "pixels" => &mut work.pixels,
                _ => {
                    return Err(self.error(format!(
                        "unknown count `{key}` in `host`: expected `{usage}`"
                    )))
                }
            };
            if seen.contains(&key) {
                return Err(self.error(format!("`{key}=` given twice in `host`")));
            }
            seen.push(key);
            *slot = self.parse_u32(key, value)?;
        }
        Ok(Command::Host(work))
    }

    fn parse_tri(&self, args: &[&str]) -> Result<Command, SceneError> {
        self.expect_args("tri", args, 12, "tri x y z w  x y z w  x y z w")?;
        let mut vertices = [[0f32; 4]; 3];
        for (i, word) in args.iter().enumerate() {
            let value: f32 = word.parse().map_err(|_| {
                self.error(format!("tri coordinate {} `{word}` is not a number", i + 1))
            })?;
            if !value.is_finite() {
                return Err(self.error(format!(
                    "tri coordinate {} is `{word}`: coordinates must be finite (no NaN or infinity)",
                    i + 1
                )));
            }
            vertices[i / 4][i % 4] = value;
        }
        Ok(Command::Tri(vertices))
    }
}

impl<R: BufRead> Iterator for SceneReader<R> {
    type Item = Result<SceneLine, SceneError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.finished {
            return None;
        }
        let item = self.next_command().transpose();
        if !matches!(item, Some(Ok(_))) {
            self.finished = true;
        }
        item
    }
}

/// Parse a whole scene held in memory.
pub fn parse_scene(text: &str, file: &str) -> Result<Vec<SceneLine>, SceneError> {
    SceneReader::new(text.as_bytes(), file).collect()
}

/// Write a command back in the scene language (floats print so that they read back exactly).
pub fn format_command(command: &Command) -> String {
    fn flag(b: bool) -> u8 {
        b as u8
    }
    match command {
        Command::Viewport { width, height } => format!("viewport {width} {height}"),
        Command::Clear => "clear".into(),
        Command::EndDraw => "end_draw".into(),
        Command::DepthFunc(f) => format!("depth_func {}", f.name()),
        Command::DepthMask(b) => format!("depth_mask {}", flag(*b)),
        Command::DepthTest(b) => format!("depth_test {}", flag(*b)),
        Command::Cull(b) => format!("cull {}", flag(*b)),
        Command::Scissor(None) => "scissor off".into(),
        Command::Scissor(Some(r)) => format!("scissor {} {} {} {}", r.x, r.y, r.width, r.height),
        Command::Begin(q) => {
            let mut s = format!("begin {} {}", q.id, q.mode.name());
            if q.mode.is_occlusion_render_mode() {
                s += &format!(" buffer={}", q.buffer_entries);
                for t in &q.tiles {
                    s += &format!(" tile={},{},{},{}", t.x, t.y, t.width, t.height);
                }
            }
            s
        }
        Command::End => "end".into(),
        Command::Wait(id) => format!("wait {id}"),
        Command::BeginConditional(id) => format!("begin_conditional {id}"),
        Command::EndConditional => "end_conditional".into(),
        Command::Host(w) => format!(
            "host nodes={} boxes={} decisions={} pixels={}",
            w.nodes, w.boxes, w.decisions, w.pixels
        ),
        Command::Swap => "swap".into(),
        Command::Tri(v) => {
            let mut s = String::from("tri");
            for vertex in v {
                for c in vertex {
                    s += &format!(" {c:?}");
                }
                s += " ";
            }
            s.trim_end().to_owned()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn error_of(text: &str) -> String {
        parse_scene(text, "s.scene").unwrap_err().to_string()
    }

    #[test]
    fn parses_every_command() {
        let text = "viewport 64 32 # size\n\nclear\ndepth_func lequal\ndepth_mask 0\ndepth_test 1\ncull 1\nscissor 1 2 3 4\nscissor off\nbegin 7 verbose buffer=9 tile=0,0,8,8 tile=8,0,8,8\ntri 0 0 0 1  1 0 0 1  0 1 0.5 1\nend_draw\nend\n";
        let lines = parse_scene(text, "s.scene").unwrap();
        assert_eq!(lines.len(), 12);
        assert_eq!(lines[10].command, Command::EndDraw);
        assert_eq!(
            lines[0].command,
            Command::Viewport {
                width: 64,
                height: 32
            }
        );
        assert_eq!(lines[1].line, 3);
        assert_eq!(lines[3].command, Command::DepthMask(false));
        assert_eq!(
            lines[6].command,
            Command::Scissor(Some(Rect::new(1, 2, 3, 4)))
        );
        let Command::Begin(q) = &lines[8].command else {
            panic!("not a begin")
        };
        assert_eq!((q.id, q.mode, q.buffer_entries), (7, QueryMode::Verbose, 9));
        assert_eq!(q.tiles, vec![Rect::new(0, 0, 8, 8), Rect::new(8, 0, 8, 8)]);
        assert_eq!(
            lines[9].command,
            Command::Tri([[0., 0., 0., 1.], [1., 0., 0., 1.], [0., 1., 0.5, 1.]])
        );
    }

    #[test]
    fn begin_defaults_to_samples_over_the_viewport() {
        let lines = parse_scene("viewport 10 20\nbegin 3\nend\n", "s").unwrap();
        let Command::Begin(q) = &lines[1].command else {
            panic!("not a begin")
        };
        assert_eq!(q.mode, QueryMode::Samples);
        assert_eq!(q.tiles, vec![Rect::new(0, 0, 10, 20)]);
        assert_eq!(q.buffer_entries, 8);
    }

    #[test]
    fn errors_name_file_line_and_expectation() {
        assert_eq!(
            error_of("viewport 4 4\n\nfrobnicate\n"),
            "s.scene:3: unknown command `frobnicate`: expected viewport, clear, depth_func, depth_mask, depth_test, cull, scissor, begin, end, tri, end_draw, wait, begin_conditional, end_conditional, host or swap"
        );
        assert!(error_of("viewport 4 4\ntri 0 0 0 1 0 0 0 1 0 0 0\n")
            .starts_with("s.scene:2: `tri` takes 12 arguments, found 11"));
        assert!(error_of("viewport 4 4\ntri 0 0 0 1 0 0 0 1 0 0 0 x\n")
            .starts_with("s.scene:2: tri coordinate 12 `x` is not a number"));
    }

    #[test]
    fn rejects_nan_and_infinity() {
        for bad in ["NaN", "inf", "-inf", "infinity", "1e39"] {
            let text = format!("viewport 4 4\ntri 0 0 0 1 0 0 0 1 0 0 0 {bad}\n");
            let message = error_of(&text);
            assert!(
                message.starts_with("s.scene:2: tri coordinate 12"),
                "{bad}: {message}"
            );
            assert!(message.contains("finite"), "{bad}: {message}");
        }
    }

    #[test]
    fn rejects_structural_mistakes() {
        assert!(error_of("clear\n").starts_with("s.scene:1: `clear` before `viewport`"));
        // A trace given as a scene is named as one (its magic had been taken for a command).
        assert_eq!(
            error_of("OCCT\r\n\x1a\nbinary"),
            "s.scene:1: an occsim trace, not a scene: `replay`, `trace info` and `trace dump` read traces; `count` and `trace gen` read scenes"
        );
        assert!(
            error_of("viewport 4 4\nviewport 4 4\n").starts_with("s.scene:2: second `viewport`")
        );
        assert!(error_of("viewport 0 4\n").contains("out of range"));
        assert!(error_of("viewport 16385 4\n").contains("out of range"));
        // Past u32 too, in the range's words (not the type's, 0 to 4294967295).
        assert_eq!(
            error_of("viewport 4 99999999999\n"),
            "s.scene:1: viewport height 99999999999 out of range: expected 1 to 16384"
        );
        assert!(error_of("viewport -4 4\n").contains("viewport width: expected a whole number"));
        assert!(
            parse_scene("viewport +4 4\n", "s").is_ok(),
            "a + leads as elsewhere"
        );
        assert!(error_of("viewport 4 4\nbegin 1 brief buffer=99999999999\n")
            .contains("buffer=99999999999 out of range: expected 8 (the brief record) to"));
        assert!(error_of("viewport 4 4\nbegin 1\nbegin 2\n")
            .starts_with("s.scene:3: `begin` inside query 1"));
        assert!(
            error_of("viewport 4 4\nend\n").starts_with("s.scene:2: `end` without an open query")
        );
        assert!(error_of("viewport 4 4\nbegin 1\n")
            .starts_with("s.scene:2: end of scene inside query 1"));
        assert!(
            error_of("viewport 4 4\nbegin 1 brief buffer=7\n").contains("buffer=7 out of range")
        );
        assert!(error_of("viewport 4 4\nbegin 1 samples tile=0,0,1,1\n").contains("take no tiles"));
        assert!(error_of("viewport 4 4\nbegin 1 brief tile=0,0,5,1\n")
            .contains("outside the 4x4 viewport"));
        assert!(error_of("viewport 4 4\nbegin 1 brief tile=0,0,0,1\n").contains("empty"));
        assert!(error_of("viewport 4 4\ndepth_mask 2\n").contains("takes 0 or 1"));
        // No line to name: the file alone (it had been `s.scene:0:`), comments alone too.
        assert_eq!(
            error_of(""),
            "s.scene: empty scene: expected `viewport W H` first"
        );
        assert!(error_of("# a comment\n\n").starts_with("s.scene: empty scene"));
    }

    #[test]
    fn a_byte_order_mark_before_the_first_line_is_accepted() {
        let lines = parse_scene("\u{feff}viewport 4 4\nclear\n", "s").unwrap();
        assert_eq!(
            lines[0].command,
            Command::Viewport {
                width: 4,
                height: 4
            }
        );
        // Only there: elsewhere it is an unknown command.
        assert!(error_of("viewport 4 4\n\u{feff}clear\n").contains("unknown command"));
    }

    #[test]
    fn closed_loop_commands_parse() {
        let text = "viewport 4 4\nbegin 5 any\nend\nhost boxes=2 nodes=7\nwait 5\nbegin_conditional 5\ntri 0 0 0 1 1 0 0 1 0 1 0 1\nend_conditional\nswap\n";
        let commands: Vec<Command> = parse_scene(text, "s")
            .unwrap()
            .into_iter()
            .map(|l| l.command)
            .collect();
        assert_eq!(
            commands[3..],
            [
                Command::Host(HostWork {
                    nodes: 7,
                    boxes: 2,
                    decisions: 0,
                    pixels: 0,
                }),
                Command::Wait(5),
                Command::BeginConditional(5),
                Command::Tri([[0., 0., 0., 1.], [1., 0., 0., 1.], [0., 1., 0., 1.]]),
                Command::EndConditional,
                Command::Swap,
            ]
        );
    }

    #[test]
    fn closed_loop_mistakes_are_named() {
        assert_eq!(
            error_of("viewport 4 4\nwait 3\n"),
            "s.scene:2: `wait 3`: query 3 has not been begun and ended above, so it has no result"
        );
        assert_eq!(
            error_of("viewport 4 4\nbegin 3\nwait 3\n"),
            "s.scene:3: `wait 3`: query 3 is still open (`end` it first), so it has no result"
        );
        assert!(error_of("viewport 4 4\nbegin_conditional 1\n")
            .contains("has not been begun and ended above"));
        assert!(
            error_of("viewport 4 4\nbegin 1\nend\nbegin_conditional 1\nbegin_conditional 1\n")
                .starts_with("s.scene:5: `begin_conditional` inside `begin_conditional 1`")
        );
        assert!(error_of("viewport 4 4\nend_conditional\n")
            .starts_with("s.scene:2: `end_conditional` without `begin_conditional`"));
        assert!(
            error_of("viewport 4 4\nbegin 1\nend\nbegin_conditional 1\n")
                .starts_with("s.scene:4: end of scene inside `begin_conditional 1`")
        );
        assert!(error_of("viewport 4 4\nhost\n").contains("at least one count"));
        assert!(error_of("viewport 4 4\nhost nodes=1 nodes=2\n").contains("given twice"));
        assert!(error_of("viewport 4 4\nhost cells=1\n").contains("unknown count `cells`"));
        assert!(error_of("viewport 4 4\nhost nodes=-1\n").contains("whole number"));
        assert!(error_of("viewport 4 4\nswap 1\n").contains("takes 0 arguments"));
    }

    #[test]
    fn format_round_trips() {
        let text = "viewport 64 32\nclear\ndepth_func gequal\nscissor 1 2 3 4\nbegin 7 verbose buffer=9 tile=0,0,8,8\ntri 0.1 0 0 1  1 0 0 1  0 1 0.5 1\nend_draw\nend\nbegin 8 any\nend\nhost nodes=3 decisions=1 pixels=99\nwait 8\nbegin_conditional 7\nend_conditional\nswap\n";
        let lines = parse_scene(text, "s").unwrap();
        let again: String = lines
            .iter()
            .map(|l| format_command(&l.command) + "\n")
            .collect();
        let reparsed = parse_scene(&again, "s").unwrap();
        let commands = |ls: &[SceneLine]| ls.iter().map(|l| l.command.clone()).collect::<Vec<_>>();
        assert_eq!(commands(&lines), commands(&reparsed));
    }
}
