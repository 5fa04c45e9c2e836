//! Mailboxes: a primitive listed in several grid cells or kd-tree leaves
//! is tested once per ray.
//!
//! Each thread keeps one array of stamps, one per primitive, and a ray
//! counter: a ray takes a new stamp, and a primitive whose slot already
//! holds it has been tested by this ray. Nothing is cleared between rays
//! (only when the 32-bit counter wraps). A query made while the thread's
//! mailbox is in use (a structure traversed from inside another one's
//! callback) gets a private one, so nesting is correct.

use std::cell::RefCell;

/// Per-thread stamps.
#[derive(Default)]
pub struct Mailbox {
    stamp: u32,
    slots: Vec<u32>,
}

thread_local! {
    static MAILBOX: RefCell<Mailbox> = RefCell::new(Mailbox::default());
}

impl Mailbox {
    /// Starts a ray over `prims` primitives.
    #[inline]
    fn start(&mut self, prims: usize) {
        if self.slots.len() < prims {
            self.slots.resize(prims, 0);
        }
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.slots.fill(0);
            self.stamp = 1;
        }
    }

    /// True the first time primitive `p` is offered during this ray.
    #[inline(always)]
    pub fn first_visit(&mut self, p: u32) -> bool {
        let slot = &mut self.slots[p as usize];
        let fresh = *slot != self.stamp;
        *slot = self.stamp;
        fresh
    }
}

/// Runs `f` with this thread's mailbox, started for a ray over `prims`
/// primitives.
#[inline]
pub fn with_mailbox<R>(prims: usize, f: impl FnOnce(&mut Mailbox) -> R) -> R {
    MAILBOX.with(|cell| match cell.try_borrow_mut() {
        Ok(mut mb) => {
            mb.start(prims);
            f(&mut mb)
        }
        Err(_) => {
            let mut mb = Mailbox::default();
            mb.start(prims);
            f(&mut mb)
        }
    })
}
