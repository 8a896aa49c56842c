//! Vehicle id → actor handle. The map holds handles only (cheap clones of channel senders); every
//! vehicle's estimator lives inside its own actor task, never behind a lock.
//!
//! Actors are created on first data or by configuration, and remove themselves when evicted.
//!
//! Admission: when `max_vehicles` are live, a new vehicle takes the place of the least recently
//! active *unconfigured* vehicle that has been silent for [`ADMISSION_IDLE_NS`] (counted in
//! `uavnav_admission_evictions_total`), so a flood of junk ids (each a vehicle nobody configured)
//! cannot lock real vehicles out for `idle_evict_s`. Configured vehicles and vehicles still
//! streaming are never displaced; only then is a new vehicle refused.

use std::collections::HashMap;
use std::sync::{Arc, RwLock, Weak};

use uavnav_core::VehicleConfig;

use crate::vehicle::VehicleShared;
use crate::vehicle::actor::{self, Ctx, VehicleHandle};

/// How long an unconfigured vehicle must have been silent before a new vehicle may take its place
/// at the vehicle limit, ns.
pub const ADMISSION_IDLE_NS: i64 = 1_000_000_000;

/// Why a vehicle could not be had.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RegistryError {
    /// The vehicle limit is reached.
    #[error("vehicle limit of {0} reached")]
    Full(usize),
    /// The service is shutting down.
    #[error("the service is shutting down")]
    Stopping,
}

/// The least recently active unconfigured vehicle silent for [`ADMISSION_IDLE_NS`], if any
/// (one pass over the map, only at the limit).
fn admission_victim(map: &mut HashMap<Arc<str>, VehicleHandle>, now_ns: i64) -> Option<Arc<str>> {
    use std::sync::atomic::Ordering::Relaxed;
    // One pass over a full map (a flood of new ids makes one per new id), which also drops the
    // handles of actors that stopped and whose exit hook has not removed them yet.
    let mut victim: Option<(i64, Arc<str>)> = None;
    map.retain(|id, h| {
        if h.is_closed() {
            return false;
        }
        if !h.shared.configured.load(Relaxed) {
            let last = h.shared.last_input_wall_ns.load(Relaxed);
            if now_ns - last >= ADMISSION_IDLE_NS && victim.as_ref().is_none_or(|(l, _)| last < *l)
            {
                victim = Some((last, Arc::clone(id)));
            }
        }
        true
    });
    victim.map(|(_, id)| id)
}

/// The vehicle registry.
#[derive(Debug)]
pub struct Registry {
    ctx: Arc<Ctx>,
    map: RwLock<HashMap<Arc<str>, VehicleHandle>>,
}

impl Registry {
    /// An empty registry whose actors share `ctx`.
    pub fn new(ctx: Arc<Ctx>) -> Arc<Self> {
        Arc::new(Self {
            ctx,
            map: RwLock::new(HashMap::new()),
        })
    }

    /// The service context.
    pub fn ctx(&self) -> &Arc<Ctx> {
        &self.ctx
    }

    /// The handle of a live vehicle.
    pub fn get(&self, id: &str) -> Option<VehicleHandle> {
        let map = self.map.read().unwrap_or_else(|p| p.into_inner());
        map.get(id).filter(|h| !h.is_closed()).cloned()
    }

    /// The vehicle's handle, starting its actor (with `config` or defaults) if needed.
    /// Returns the handle and whether it was created.
    pub fn get_or_create(
        self: &Arc<Self>,
        id: &str,
        config: Option<&VehicleConfig>,
    ) -> Result<(VehicleHandle, bool), RegistryError> {
        if let Some(h) = self.get(id) {
            return Ok((h, false));
        }
        if self.ctx.hub.is_stopping() {
            return Err(RegistryError::Stopping);
        }
        let mut map = self.map.write().unwrap_or_else(|p| p.into_inner());
        if let Some(h) = map.get(id).filter(|h| !h.is_closed()) {
            return Ok((h.clone(), false));
        }
        let limit = self.ctx.vehicles.max_vehicles;
        // Below the limit, creation costs the same however many vehicles there are.
        let victim = if map.len() >= limit {
            admission_victim(&mut map, crate::vehicle::wall_ns())
        } else {
            None
        };
        if map.len() >= limit {
            let victim = victim.ok_or(RegistryError::Full(limit))?;
            if let Some(h) = map.remove(&victim) {
                h.try_stop();
                self.ctx.metrics.admission_evictions.inc();
                tracing::debug!(vehicle = ?victim, "idle unconfigured vehicle displaced at the vehicle limit");
                // Its actor's exit hook announces it gone (lifecycle) when it stops.
            }
        }
        let key: Arc<str> = Arc::from(id);
        let shared = Arc::new(VehicleShared::new(Arc::clone(&key)));
        let cfg = config.cloned().unwrap_or_default();
        if config.is_some() {
            shared
                .configured
                .store(true, std::sync::atomic::Ordering::Relaxed);
        }
        let handle = actor::spawn(
            Arc::clone(&shared),
            cfg,
            Arc::clone(&self.ctx),
            self.exit_hook(&shared),
        );
        map.insert(Arc::clone(&key), handle.clone());
        self.ctx.metrics.vehicles.set(map.len() as i64);
        if config.is_some() {
            shared.announce(&self.ctx.hub.lifecycle);
        }
        Ok((handle, true))
    }

    /// Removes the vehicle when its actor ends, unless a newer actor already took the id.
    fn exit_hook(self: &Arc<Self>, shared: &Arc<VehicleShared>) -> Box<dyn FnOnce(bool) + Send> {
        let weak: Weak<Self> = Arc::downgrade(self);
        let shared = Arc::clone(shared);
        Box::new(move |evicted| {
            let Some(reg) = weak.upgrade() else { return };
            let mut map = reg.map.write().unwrap_or_else(|p| p.into_inner());
            if map
                .get(&shared.id)
                .is_some_and(|h| Arc::ptr_eq(&h.shared, &shared))
            {
                map.remove(&shared.id);
            }
            reg.ctx.metrics.vehicles.set(map.len() as i64);
            // A map never gives back its capacity on its own: after a flood has gone, do.
            if map.capacity() > 64 && map.len() * 4 < map.capacity() {
                map.shrink_to_fit();
            }
            // Its camera's pixels go back to the global budget.
            reg.ctx
                .camera_pixels
                .swap(crate::vehicle::budgets::camera_pixels(shared.camera()), 0);
            if evicted {
                reg.ctx.metrics.evictions.inc();
            }
            let _ = reg.ctx.hub.lifecycle.send((Arc::clone(&shared.id), false));
        })
    }

    /// Live vehicles sorted by id, optionally filtered by prefix.
    pub fn list(&self, prefix: &str) -> Vec<VehicleHandle> {
        let map = self.map.read().unwrap_or_else(|p| p.into_inner());
        let mut v: Vec<VehicleHandle> = map
            .values()
            .filter(|h| !h.is_closed() && h.shared.id.starts_with(prefix))
            .cloned()
            .collect();
        v.sort_by(|a, b| a.shared.id.cmp(&b.shared.id));
        v
    }

    /// Number of live vehicles.
    pub fn len(&self) -> usize {
        self.map.read().map(|m| m.len()).unwrap_or(0)
    }

    /// Whether no vehicle is live.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Every handle, removing them from the map (shutdown).
    pub fn take_all(&self) -> Vec<VehicleHandle> {
        let mut map = self.map.write().unwrap_or_else(|p| p.into_inner());
        map.drain().map(|(_, h)| h).collect()
    }
}
