//! The geometry stage: per-vertex transform and lighting and per-triangle setup of every
//! submitted triangle (those culled or clipped away included), batch by batch.
//!
//! Rules:
//! - On the host ([`Geometry::OnHost`], the O2): the host CPU transforms the batch, busy
//!   `round(v * per_vertex + t * per_triangle)` cycles; the batch's primitives are released
//!   to the rasterizer when it is done. A batch discarded by conditional rendering is
//!   transformed all the same (the driver cannot know without waiting; the rendering engine
//!   discards it).
//! - On Geometry Engines ([`Geometry::Engines`], the InfiniteReality): the host writes the
//!   batch's vertices over the bus (busy `round(v * bus_per_vertex)`), then the engine free
//!   first takes the whole batch, from `max(engine free, host done)`, for
//!   `round(v * per_vertex + t * per_triangle)` cycles. Batches leave in order (a batch is
//!   released no earlier than the one before it) into the FIFO to the raster boards, whose
//!   65,536 vertices (V2) no batch fills, so the engines never block on it. Discarded batches
//!   cost the engines nothing: the pipeline holds and then drops them.

use crate::blocks::host::{cost, Host};
use crate::timeline::{note, State, Track};
use occsim_traces::GeometryBatch;

#[derive(Clone, Debug)]
pub enum Geometry {
    OnHost {
        per_vertex: f64,
        per_triangle: f64,
    },
    Engines {
        per_vertex: f64,
        per_triangle: f64,
        bus_per_vertex: f64,
        /// The first free cycle of each engine.
        free: Vec<u64>,
        last_release: u64,
    },
}

impl Geometry {
    /// The same stage on a timeline `base` cycles later: its engines' free cycles and its
    /// last release moved back by `base` (where they were earlier, at 0: idle).
    pub fn moved_back(&self, base: u64) -> Geometry {
        let mut moved = self.clone();
        if let Geometry::Engines {
            free, last_release, ..
        } = &mut moved
        {
            free.iter_mut()
                .for_each(|cycle| *cycle = cycle.saturating_sub(base));
            *last_release = last_release.saturating_sub(base);
        }
        moved
    }

    /// Process `batch` (the host's per-draw cost already paid); returns the cycle its
    /// primitives are released to the rasterizer and the geometry stage's busy cycles.
    pub fn batch(&mut self, batch: &GeometryBatch, host: &mut Host) -> (u64, u64) {
        let (v, t) = (batch.vertices as u64, batch.triangles as u64);
        match self {
            Geometry::OnHost {
                per_vertex,
                per_triangle,
            } => {
                let busy = cost(v, *per_vertex) + cost(t, *per_triangle);
                host.spend(busy);
                let done = host.now();
                note(
                    &host.timeline,
                    Track::Geometry(0),
                    State::Busy,
                    done - busy,
                    done,
                );
                (done, busy)
            }
            Geometry::Engines {
                per_vertex,
                per_triangle,
                bus_per_vertex,
                free,
                last_release,
            } => {
                host.spend(cost(v, *bus_per_vertex));
                if batch.discarded {
                    return (host.now().max(*last_release), 0);
                }
                let busy = cost(v, *per_vertex) + cost(t, *per_triangle);
                // Least busy first: the engine free earliest (the lowest-numbered on ties).
                let engine = (0..free.len()).min_by_key(|&e| free[e]).unwrap_or(0);
                let done = free[engine].max(host.now()) + busy;
                free[engine] = done;
                let lane = Track::Geometry(engine as u32);
                note(&host.timeline, lane, State::Busy, done - busy, done);
                *last_release = (*last_release).max(done);
                (*last_release, busy)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::blocks::host::HostCosts;

    fn batch(vertices: u32, triangles: u32) -> GeometryBatch {
        GeometryBatch {
            vertices,
            triangles,
            starts_draw: true,
            discarded: false,
        }
    }

    fn idle_host() -> Host {
        Host::new(HostCosts::from_host_cycles(1.0, 1.0, [0; 6]))
    }

    #[test]
    fn on_the_host_the_cpu_is_busy_and_releases_at_its_end() {
        let mut geometry = Geometry::OnHost {
            per_vertex: 2.0,
            per_triangle: 5.0,
        };
        let mut host = idle_host();
        // 6 vertices * 2 + 2 triangles * 5 = 22.
        assert_eq!(geometry.batch(&batch(6, 2), &mut host), (22, 22));
        assert_eq!(host.busy_cycles, 22);
    }

    #[test]
    fn engines_take_batches_in_parallel_and_release_them_in_order() {
        let mut geometry = Geometry::Engines {
            per_vertex: 10.0,
            per_triangle: 0.0,
            bus_per_vertex: 1.0,
            free: vec![0, 0],
            last_release: 0,
        };
        let mut host = idle_host();
        // Batch 1: bus 30 (host done at 30), engine 0 from 30 for 300: released at 330.
        assert_eq!(geometry.batch(&batch(30, 10), &mut host), (330, 300));
        // Batch 2: bus 3 (host at 33), engine 1 from 33 for 30: done at 63, but released
        // after batch 1 at 330.
        assert_eq!(geometry.batch(&batch(3, 1), &mut host), (330, 30));
        // Batch 3: bus 3 (host at 36), engine 1 again (free at 63): done at 93 -> 330.
        assert_eq!(geometry.batch(&batch(3, 1), &mut host), (330, 30));
        assert_eq!(host.now(), 36);
        let discarded = GeometryBatch {
            discarded: true,
            ..batch(3, 1)
        };
        assert_eq!(geometry.batch(&discarded, &mut host), (330, 0));
        assert_eq!(host.now(), 39, "the host still sent its vertices");
    }
}
