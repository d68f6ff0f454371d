// Fixed-size time series whose latest N samples are always one contiguous Float64Array view.
// Each sample is written twice (at i and i + N), so the window is subarray(start, start + N)
// with no copying and no growth: memory is fixed however long the page stays open.

export class Ring {
  constructor(capacity) {
    this.capacity = capacity;
    this.data = new Float64Array(2 * capacity);
    this.next = 0;
    this.count = 0;
  }

  push(value) {
    const v = value === null || value === undefined ? NaN : value;
    this.data[this.next] = v;
    this.data[this.next + this.capacity] = v;
    this.next = (this.next + 1) % this.capacity;
    this.count = Math.min(this.count + 1, this.capacity);
  }

  view() {
    const start = this.count < this.capacity ? 0 : this.next;
    return this.data.subarray(start, start + this.count);
  }

  // A plain array with null for unknown samples: plotly draws NaN in typed arrays as 0,
  // but leaves a gap at null. A fresh array per frame keeps plotly's change detection simple.
  values() {
    return Array.from(this.view(), (v) => (Number.isNaN(v) ? null : v));
  }

  clear() {
    this.next = 0;
    this.count = 0;
  }
}
