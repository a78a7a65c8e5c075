//! The map from session id to handle. A short std mutex: lookups only, never held across `.await`.

use std::collections::HashMap;
use std::sync::Mutex;

use super::SessionHandle;

/// Live sessions.
#[derive(Debug, Default)]
pub struct Registry {
    sessions: Mutex<HashMap<String, SessionHandle>>,
}

impl Registry {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, SessionHandle>> {
        // A panic while holding this lock cannot leave the map half-updated
        // (every operation is a single insert/remove), so poisoning is ignored.
        self.sessions.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The handle of session `id`.
    pub fn get(&self, id: &str) -> Option<SessionHandle> {
        self.lock().get(id).cloned()
    }

    /// Inserts unless the id is taken or the map holds `max` sessions;
    /// gives the handle back on failure.
    pub fn try_insert(
        &self,
        handle: SessionHandle,
        max: usize,
    ) -> Result<(), (SessionHandle, bool)> {
        let mut map = self.lock();
        if map.contains_key(handle.id()) {
            return Err((handle, true));
        }
        if map.len() >= max {
            return Err((handle, false));
        }
        map.insert(handle.id().to_owned(), handle);
        Ok(())
    }

    /// Removes and returns session `id`.
    pub fn remove(&self, id: &str) -> Option<SessionHandle> {
        self.lock().remove(id)
    }

    /// Removes `handle`'s session if the registry still holds that same actor (not a
    /// newer one for the same id); true when it did.
    pub fn remove_if_same(&self, handle: &SessionHandle) -> bool {
        let mut map = self.lock();
        if map.get(handle.id()).is_some_and(|h| h.same_actor(handle)) {
            map.remove(handle.id());
            true
        } else {
            false
        }
    }

    /// Every handle, ordered by id.
    pub fn list(&self) -> Vec<SessionHandle> {
        let mut all: Vec<_> = self.lock().values().cloned().collect();
        all.sort_by(|a, b| a.id().cmp(b.id()));
        all
    }

    /// Number of sessions.
    pub fn len(&self) -> usize {
        self.lock().len()
    }

    /// True when there are no sessions.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
