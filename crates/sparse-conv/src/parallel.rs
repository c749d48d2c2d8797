//! Sharing an output buffer among parallel tasks that each write their own disjoint part.

/// A raw pointer tasks share, each writing its own disjoint part.
pub(crate) struct SyncPtr<T>(pub(crate) *mut T);
unsafe impl<T> Send for SyncPtr<T> {}
unsafe impl<T> Sync for SyncPtr<T> {}
