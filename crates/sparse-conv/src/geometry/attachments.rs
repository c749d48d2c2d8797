//! What a backend derives from a map or a level and keeps with it (its tables or coordinates on a
//! device), freed with it.

use std::any::Any;
use std::sync::{Arc, Mutex};

/// Values of any type kept with their owner, at most a few (one per device).
#[derive(Default)]
pub struct Attachments {
    values: Mutex<Vec<Arc<dyn Any + Send + Sync>>>,
}

impl Attachments {
    /// The first value of type `T` that `matches`, made with `make` and kept if there is none.
    pub fn get_or_make<T: Any + Send + Sync>(&self, matches: impl Fn(&T) -> bool, make: impl FnOnce() -> T) -> Arc<T> {
        let mut values = self.values.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let found = values.iter().find_map(|a| a.clone().downcast::<T>().ok().filter(|t| matches(t)));
        found.unwrap_or_else(|| {
            let made = Arc::new(make());
            values.push(made.clone());
            made
        })
    }

    /// Keeps `value`.
    #[cfg_attr(not(feature = "cube"), allow(dead_code))]
    pub fn insert<T: Any + Send + Sync>(&self, value: Arc<T>) {
        self.values.lock().unwrap_or_else(|poisoned| poisoned.into_inner()).push(value);
    }
}
