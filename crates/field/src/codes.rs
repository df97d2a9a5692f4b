//! Coded-target numbering (`docs/coded-targets.md`): 12 sectors read
//! counter-clockwise seen from +Z, first-read bit most significant, canonical
//! value the smallest rotation, ids 1..=350 numbering the sorted canonical
//! values without 0 and 4095.

/// Number of code sectors.
pub const SECTORS: u32 = 12;
/// Mask of a 12-bit word.
pub const MASK: u16 = 0x0fff;
/// Number of code ids.
pub const COUNT: usize = 350;

/// Rotates a 12-bit word left by `k` sectors (start reading `k` sectors later).
#[inline]
pub fn rotate(v: u16, k: u32) -> u16 {
    let v = v & MASK;
    let k = k % SECTORS;
    ((v << k) | (v >> (SECTORS - k))) & MASK
}

/// The canonical value: the smallest of the 12 rotations.
#[inline]
pub fn canonical(v: u16) -> u16 {
    (0..SECTORS).map(|k| rotate(v, k)).min().unwrap_or(0)
}

/// The 350 canonical values in ascending order; entry `id - 1` is the value of `id`.
pub fn table() -> &'static [u16; COUNT] {
    static TABLE: std::sync::OnceLock<[u16; COUNT]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [0u16; COUNT];
        let mut n = 0;
        for v in 1..MASK {
            if canonical(v) == v {
                t[n] = v;
                n += 1;
            }
        }
        assert_eq!(n, COUNT, "there are 350 non-trivial 12-bit necklaces");
        t
    })
}

/// The canonical value of code `id`, `None` outside 1..=350.
pub fn value_of(id: u64) -> Option<u16> {
    (1..=COUNT as u64)
        .contains(&id)
        .then(|| table()[id as usize - 1])
}

/// The id of any 12-bit reading (any starting sector), `None` for 0 and 4095.
pub fn id_of(reading: u16) -> Option<u64> {
    let c = canonical(reading & MASK);
    table().binary_search(&c).ok().map(|i| i as u64 + 1)
}

/// Whether code `id` has an even number of bright sectors (the codes that
/// designed plates use).
pub fn is_even(id: u64) -> bool {
    value_of(id).is_some_and(|v| v.count_ones().is_multiple_of(2))
}

/// The even code ids in ascending order.
pub fn even_ids() -> impl Iterator<Item = u64> {
    (1..=COUNT as u64).filter(|&id| is_even(id))
}

/// Bit of sector `k` (0 = first read, the most significant) of code `id`'s
/// canonical value.
pub fn sector_bit(value: u16, k: u32) -> bool {
    (value >> (SECTORS - 1 - (k % SECTORS))) & 1 == 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_matches_the_spec() {
        let spec = [
            (1, 0b000000000001),
            (2, 0b000000000011),
            (3, 0b000000000101),
            (4, 0b000000000111),
            (5, 0b000000001001),
            (17, 0b000000100001),
            (42, 0b000001010011),
            (100, 0b000011001111),
            (200, 0b000111010011),
            (300, 0b001110101101),
            (348, 0b011110111111),
            (349, 0b011111011111),
            (350, 0b011111111111),
        ];
        for (id, v) in spec {
            assert_eq!(value_of(id), Some(v), "id {id}");
            assert_eq!(id_of(v), Some(id));
        }
    }

    #[test]
    fn every_rotation_reads_the_same_id() {
        for id in 1..=350 {
            let v = value_of(id).unwrap();
            for k in 0..12 {
                assert_eq!(id_of(rotate(v, k)), Some(id));
            }
        }
        assert_eq!(id_of(0), None);
        assert_eq!(id_of(MASK), None);
    }

    #[test]
    fn even_codes_are_178_and_one_misread_sector_never_gives_another() {
        let even: Vec<u64> = even_ids().collect();
        assert_eq!(even.len(), 178);
        assert_eq!(&even[..10], &[2, 3, 5, 8, 9, 12, 14, 15, 17, 20]);
        for &id in &even {
            let v = value_of(id).unwrap();
            for bit in 0..12 {
                let flipped = v ^ (1 << bit);
                if let Some(other) = id_of(flipped) {
                    assert!(
                        !is_even(other),
                        "id {id} with one flipped sector reads even id {other}"
                    );
                }
            }
        }
    }
}
