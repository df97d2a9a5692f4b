//! A uniform grid over the image for finding detections near a projected
//! target: fixed capacity, cleared per frame without allocation.

/// Bucket grid of point indices.
#[derive(Debug, Clone)]
pub(crate) struct Grid {
    cell: f64,
    cols: usize,
    rows: usize,
    head: Vec<i32>,
    next: Vec<i32>,
    ids: Vec<u32>,
    capacity: usize,
}

impl Grid {
    /// A grid of `cell`-pixel buckets for a `width × height` image holding
    /// up to `capacity` points.
    pub fn new(width: u32, height: u32, cell: u32, capacity: usize) -> Self {
        let cols = (width as usize).div_ceil(cell as usize).max(1);
        let rows = (height as usize).div_ceil(cell as usize).max(1);
        Grid {
            cell: cell as f64,
            cols,
            rows,
            head: vec![-1; cols * rows],
            next: Vec::with_capacity(capacity),
            ids: Vec::with_capacity(capacity),
            capacity,
        }
    }

    /// Removes every point.
    pub fn clear(&mut self) {
        self.head.fill(-1);
        self.next.clear();
        self.ids.clear();
    }

    fn cell_of(&self, col: f64, row: f64) -> (usize, usize) {
        let cx = (col / self.cell).floor().clamp(0.0, (self.cols - 1) as f64) as usize;
        let cy = (row / self.cell).floor().clamp(0.0, (self.rows - 1) as f64) as usize;
        (cx, cy)
    }

    /// Adds point `id` (an index chosen by the caller, `< capacity`) at `(col, row)`.
    /// Points beyond the capacity are ignored.
    pub fn insert(&mut self, id: u32, col: f64, row: f64) {
        if self.next.len() >= self.capacity || !(col.is_finite() && row.is_finite()) {
            return;
        }
        let slot = self.next.len();
        let (cx, cy) = self.cell_of(col, row);
        let h = &mut self.head[cy * self.cols + cx];
        self.next.push(*h);
        self.ids.push(id);
        *h = slot as i32;
    }

    /// Calls `f` with the id of every point in the cells within `radius` of
    /// `(col, row)` (a superset of the points within `radius`).
    pub fn for_each_near(&self, col: f64, row: f64, radius: f64, mut f: impl FnMut(u32)) {
        let (x0, y0) = self.cell_of(col - radius, row - radius);
        let (x1, y1) = self.cell_of(col + radius, row + radius);
        for cy in y0..=y1 {
            for cx in x0..=x1 {
                let mut s = self.head[cy * self.cols + cx];
                while s >= 0 {
                    f(self.ids[s as usize]);
                    s = self.next[s as usize];
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_points_near_a_position() {
        let mut g = Grid::new(100, 80, 16, 10);
        g.insert(0, 10.0, 10.0);
        g.insert(1, 50.0, 50.0);
        g.insert(2, 52.0, 49.0);
        g.insert(3, 99.0, 79.0);
        let mut found = Vec::new();
        g.for_each_near(51.0, 50.0, 3.0, |k| found.push(k));
        found.sort();
        assert_eq!(found, vec![1, 2]);
        g.clear();
        let mut n = 0;
        g.for_each_near(51.0, 50.0, 100.0, |_| n += 1);
        assert_eq!(n, 0);
    }
}
