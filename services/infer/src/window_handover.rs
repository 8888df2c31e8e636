//! The hand-over between the thread that receives events and the inference thread. Live, a
//! new window replaces one still waiting, so a slow model always works on the newest window and
//! never makes the receiver (hence the ingest) wait. Under `--every-window` the windows queue
//! instead, so every one is forecast, as `evgate eval` does: the queue then grows while the
//! model lags (a replay's length of windows at most).

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex, MutexGuard};

pub struct WindowHandover<T> {
    every_window: bool,
    state: Mutex<HandoverState<T>>,
    changed: Condvar,
}

struct HandoverState<T> {
    items: VecDeque<T>,
    closed: bool,
}

impl<T> WindowHandover<T> {
    /// Keeps only the newest item, or every item in order when `every_window`.
    pub fn new(every_window: bool) -> Self {
        Self {
            every_window,
            state: Mutex::new(HandoverState {
                items: VecDeque::new(),
                closed: false,
            }),
            changed: Condvar::new(),
        }
    }

    /// Leaves `item` for the taker and returns the item it displaced, if one was still waiting
    /// (never under `every_window`).
    pub fn put(&self, item: T) -> Option<T> {
        let mut state = self.lock();
        let displaced = if self.every_window {
            None
        } else {
            state.items.pop_front()
        };
        state.items.push_back(item);
        drop(state);
        self.changed.notify_one();
        displaced
    }

    /// Waits for an item, oldest first; `None` once closed and empty.
    pub fn take(&self) -> Option<T> {
        let mut state = self.lock();
        loop {
            if let Some(item) = state.items.pop_front() {
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

    /// Wakes the taker for good once the hand-over is drained.
    pub fn close(&self) {
        self.lock().closed = true;
        self.changed.notify_all();
    }

    fn lock(&self) -> MutexGuard<'_, HandoverState<T>> {
        // The state stays consistent under a panic elsewhere: no change can stop half-way.
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
        let slot = WindowHandover::new(false);
        assert_eq!(slot.put(1), None);
        assert_eq!(slot.put(2), Some(1));
        assert_eq!(slot.take(), Some(2));
    }

    #[test]
    fn under_every_window_items_queue_in_order() {
        let queue = WindowHandover::new(true);
        for item in 1..=3 {
            assert_eq!(queue.put(item), None);
        }
        queue.close();
        assert_eq!(
            std::iter::from_fn(|| queue.take()).collect::<Vec<_>>(),
            vec![1, 2, 3]
        );
    }

    #[test]
    fn close_ends_a_waiting_taker_after_the_last_item() {
        let slot = Arc::new(WindowHandover::new(false));
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
