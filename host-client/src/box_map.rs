//! Per-box state looked up once per record: [`BoxMap`] keeps each box's value in a vector
//! and remembers the box of the last look-up, so the records of one datagram (all from one
//! box) cost a comparison of keys, not a hash each.

use crate::decoder::BoxKey;
use std::cell::Cell;
use std::collections::HashMap;

/// Values by [`BoxKey`], in the order the boxes were first seen.
#[derive(Debug, Clone)]
pub(crate) struct BoxMap<V> {
    entries: Vec<(BoxKey, V)>,
    index: HashMap<BoxKey, usize>,
    /// The entry of the last look-up.
    current: Cell<usize>,
}

impl<V> Default for BoxMap<V> {
    fn default() -> Self {
        BoxMap {
            entries: Vec::new(),
            index: HashMap::new(),
            current: Cell::new(0),
        }
    }
}

impl<V> BoxMap<V> {
    /// The entry index of `key`, if it has one.
    #[inline]
    fn find(&self, key: &BoxKey) -> Option<usize> {
        if self.entries.is_empty() {
            return None;
        }
        let current = self.current.get();
        if self.entries.get(current).is_some_and(|(k, _)| k == key) {
            return Some(current);
        }
        let i = *self.index.get(key)?;
        self.current.set(i);
        Some(i)
    }

    /// The value of `key`.
    #[inline]
    pub(crate) fn get(&self, key: &BoxKey) -> Option<&V> {
        self.find(key).map(|i| &self.entries[i].1)
    }

    /// The value of `key`, made by `new` when the box is new.
    #[inline]
    pub(crate) fn get_or_insert_with(&mut self, key: BoxKey, new: impl FnOnce() -> V) -> &mut V {
        let i = match self.find(&key) {
            Some(i) => i,
            None => {
                self.entries.push((key, new()));
                let i = self.entries.len() - 1;
                self.index.insert(key, i);
                self.current.set(i);
                i
            }
        };
        &mut self.entries[i].1
    }

    /// Every box with its value.
    pub(crate) fn iter(&self) -> impl Iterator<Item = (&BoxKey, &V)> {
        self.entries.iter().map(|(k, v)| (k, v))
    }

    /// Every box with its value, to change.
    pub(crate) fn iter_mut(&mut self) -> impl Iterator<Item = (&BoxKey, &mut V)> {
        self.entries.iter_mut().map(|(k, v)| (&*k, v))
    }

    /// The boxes.
    pub(crate) fn keys(&self) -> impl Iterator<Item = &BoxKey> {
        self.entries.iter().map(|(k, _)| k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::SocketAddr;

    fn key(box_id: u16, port: Option<u16>) -> BoxKey {
        BoxKey {
            box_id,
            source: port.map(|p| SocketAddr::from(([192, 0, 2, 1], p))),
        }
    }

    #[test]
    fn each_key_keeps_its_own_value_whatever_the_order_of_look_ups() {
        let mut m = BoxMap::default();
        let keys = [
            key(1, None),
            key(1, Some(5)),
            key(2, Some(5)),
            key(1, Some(6)),
        ];
        for (n, k) in keys.iter().enumerate() {
            *m.get_or_insert_with(*k, || 0) += n + 10;
        }
        // interleaved look-ups, the cached one and others
        for &i in &[3usize, 3, 0, 2, 2, 1, 0, 3] {
            assert_eq!(m.get(&keys[i]), Some(&(i + 10)), "{i}");
        }
        assert_eq!(m.get(&key(3, None)), None);
        assert_eq!(m.get(&keys[1]), Some(&11), "a miss leaves the others found");
        *m.get_or_insert_with(keys[0], || 99) += 1;
        assert_eq!(
            m.get(&keys[0]),
            Some(&11),
            "an existing value is not replaced"
        );
        assert_eq!(m.keys().copied().collect::<Vec<_>>(), keys);
        for (_, v) in m.iter_mut() {
            *v = 0;
        }
        assert!(m.iter().all(|(_, v)| *v == 0));
    }
}
