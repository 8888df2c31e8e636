//! Front-to-back writing into a loaned, uninitialised shared-memory slice, so a producer can fill
//! a sample in place (no intermediate vector) without unsafe code of its own.

use std::mem::MaybeUninit;

/// Writes items into the slots of a loaned slice in order. Items beyond the slice are not
/// written but counted ([`overflowed`](Self::overflowed)); slots left unwritten are zeroed by
/// the publisher before sending.
pub struct SliceWriter<'a, T> {
    slots: &'a mut [MaybeUninit<T>],
    written: usize,
    overflowed: usize,
}

impl<'a, T: Copy> SliceWriter<'a, T> {
    pub fn new(slots: &'a mut [MaybeUninit<T>]) -> Self {
        Self {
            slots,
            written: 0,
            overflowed: 0,
        }
    }

    /// Appends one item.
    #[inline(always)]
    pub fn push(&mut self, item: T) {
        match self.slots.get_mut(self.written) {
            Some(slot) => {
                slot.write(item);
                self.written += 1;
            }
            None => self.overflowed += 1,
        }
    }

    /// Appends `items` with one copy.
    #[inline]
    pub fn extend_from_slice(&mut self, items: &[T]) {
        let room = self.slots.len() - self.written;
        let fitting = items.len().min(room);
        let source = &items[..fitting];
        // SAFETY: `MaybeUninit<T>` has the layout of `T`, so the items read as initialised
        // `MaybeUninit<T>` values for as long as `items` is borrowed.
        let source: &[MaybeUninit<T>] =
            unsafe { std::slice::from_raw_parts(source.as_ptr().cast(), source.len()) };
        self.slots[self.written..self.written + fitting].copy_from_slice(source);
        self.written += fitting;
        self.overflowed += items.len() - fitting;
    }

    /// The items written so far.
    pub fn as_written(&self) -> &[T] {
        // SAFETY: the first `written` slots were initialised by `push` or
        // `extend_from_slice`, and `MaybeUninit<T>` has the layout of `T`.
        unsafe { std::slice::from_raw_parts(self.slots.as_ptr().cast::<T>(), self.written) }
    }

    /// Items written so far.
    pub fn written(&self) -> usize {
        self.written
    }

    /// Items that did not fit.
    pub fn overflowed(&self) -> usize {
        self.overflowed
    }

    /// Slots of the slice.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether the slice has no slots.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// Initialises the unwritten slots with `filler`; returns how many there were.
    pub(crate) fn fill_rest(&mut self, filler: T) -> usize {
        let rest = &mut self.slots[self.written..];
        for slot in rest.iter_mut() {
            slot.write(filler);
        }
        rest.len()
    }
}

impl evgate_core::EventSink for SliceWriter<'_, evgate_core::Event> {
    #[inline(always)]
    fn push(&mut self, event: evgate_core::Event) {
        SliceWriter::push(self, event);
    }

    fn extend_from_slice(&mut self, events: &[evgate_core::Event]) {
        SliceWriter::extend_from_slice(self, events);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn written(slots: &[MaybeUninit<u32>]) -> Vec<u32> {
        // SAFETY: the tests only read slots they initialised.
        slots
            .iter()
            .map(|slot| unsafe { slot.assume_init() })
            .collect()
    }

    #[test]
    fn items_land_in_order_and_the_rest_is_filled() {
        let mut slots = [MaybeUninit::<u32>::uninit(); 6];
        let mut writer = SliceWriter::new(&mut slots);
        writer.push(1);
        writer.extend_from_slice(&[2, 3]);
        writer.push(4);
        assert_eq!((writer.written(), writer.overflowed()), (4, 0));
        assert_eq!(writer.as_written(), [1, 2, 3, 4]);
        assert_eq!(writer.fill_rest(0), 2);
        assert_eq!(written(&slots), [1, 2, 3, 4, 0, 0]);
    }

    #[test]
    fn items_beyond_the_slice_are_counted_not_written() {
        let mut slots = [MaybeUninit::<u32>::uninit(); 3];
        let mut writer = SliceWriter::new(&mut slots);
        writer.extend_from_slice(&[1, 2]);
        writer.extend_from_slice(&[3, 4, 5]);
        writer.push(6);
        assert_eq!((writer.written(), writer.overflowed()), (3, 3));
        assert_eq!(writer.fill_rest(0), 0);
        assert_eq!(written(&slots), [1, 2, 3]);
    }
}
