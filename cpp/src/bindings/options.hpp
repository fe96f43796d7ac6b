// Option parsing shared by the clips and convert bindings.
#pragma once
#include "bsp/clips/clips.hpp"
#include "common.hpp"

namespace bsp::py_bind {

template <class T>
inline T take(py::dict& d, const char* key, T fallback) {
  if (!d.contains(key)) return fallback;
  T v = d[key].cast<T>();
  d.attr("pop")(key);
  return v;
}

inline ClipOptions clip_options(py::dict& d) {
  ClipOptions c;
  c.length = take(d, "clip_length", c.length);
  c.stride = take(d, "clip_stride", c.stride);
  c.eval_stride = take(d, "eval_clip_stride", c.eval_stride);
  c.min_video_length = take(d, "min_video_length", c.min_video_length);
  c.label_fraction = take(d, "label_fraction", c.label_fraction);
  c.benchmark = take(d, "benchmark", c.benchmark);
  c.val_frac = take(d, "val_frac", c.val_frac);
  c.test_frac = take(d, "test_frac", c.test_frac);
  c.seed = take(d, "seed", c.seed);
  c.balance = take(d, "balance", c.balance);
  return c;
}

inline void no_leftovers(const py::dict& d) {
  if (py::len(d))
    throw py::value_error("unknown option(s): " + py::str(py::list(d.attr("keys")())).cast<std::string>());
}

}  // namespace bsp::py_bind
