//! A one-item hand-over between the thread that receives events and the inference thread: a
//! new window replaces one still waiting, so a slow model always works on the newest window and
//! never makes the receiver (hence the ingest) wait.

use std::sync::{Condvar, Mutex, MutexGuard};

pub struct LatestSlot<T> {
    state: Mutex<SlotState<T>>,
    changed: Condvar,
}

struct SlotState<T> {
    item: Option<T>,
    closed: bool,
}

impl<T> Default for LatestSlot<T> {
    fn default() -> Self {
        Self {
            state: Mutex::new(SlotState {
                item: None,
                closed: false,
            }),
            changed: Condvar::new(),
        }
    }
}

impl<T> LatestSlot<T> {
    /// Leaves `item` for the taker and returns the item it displaced, if one was still waiting.
    pub fn put(&self, item: T) -> Option<T> {
        let displaced = self.lock().item.replace(item);
        self.changed.notify_one();
        displaced
    }

    /// Waits for an item; `None` once the slot is closed and empty.
    pub fn take(&self) -> Option<T> {
        let mut state = self.lock();
        loop {
            if let Some(item) = state.item.take() {
                return Some(item);
            }
            if state.closed {
                return None;
            }
            state = self
                .changed
                .wait(state)
                .unwrap_or_else(|poisoned| poisoned.into_inner());
        }
    }

    /// Wakes the taker for good once the slot is drained.
    pub fn close(&self) {
        self.lock().closed = true;
        self.changed.notify_all();
    }

    fn lock(&self) -> MutexGuard<'_, SlotState<T>> {
        // The state stays consistent under a panic elsewhere: every change is one assignment.
        self.state
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn a_new_item_displaces_the_waiting_one() {
        let slot = LatestSlot::default();
        assert_eq!(slot.put(1), None);
        assert_eq!(slot.put(2), Some(1));
        assert_eq!(slot.take(), Some(2));
    }

    #[test]
    fn close_ends_a_waiting_taker_after_the_last_item() {
        let slot = Arc::new(LatestSlot::default());
        let taker = {
            let slot = Arc::clone(&slot);
            std::thread::spawn(move || std::iter::from_fn(|| slot.take()).collect::<Vec<i32>>())
        };
        slot.put(7);
        slot.close();
        let taken = taker.join().unwrap();
        assert!(taken == vec![7] || taken.is_empty(), "{taken:?}");
        assert_eq!(slot.take(), None);
    }
}
