// Writing one split of clips: per-clip arrays are filled in parallel into a batch buffer,
// then written by the one thread that owns the HDF5 file (libhdf5 is not thread-safe).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <exception>
#include <thread>
#include <utility>

#include "bsp/common/parallel.hpp"
#include "bsp/geometry/kinematics.hpp"
#include "convert_internal.hpp"

namespace bsp::detail {
namespace {

constexpr int J = 26;

struct Field {
  std::string name;
  h5::Type type;
  std::vector<hsize_t> tail;  // shape after (N, L) for per-frame fields
  bool big;                   // eligible for compression
  std::size_t per_frame() const {
    std::size_t n = 1;
    for (auto d : tail) n *= d;
    return n;
  }
  std::size_t elem() const { return type == h5::Type::I64 ? 8 : type == h5::Type::U8 ? 1 : 4; }
};

const std::vector<Field>& frame_fields() {
  static const std::vector<Field> f = {
      {"projection_2d", h5::Type::F32, {J, 2}, false},
      {"targets/relative_pose_loc", h5::Type::F32, {J, 3}, true},
      {"targets/relative_pose_rot", h5::Type::F32, {J, 3, 3}, true},
      {"targets/absolute_pose_loc", h5::Type::F32, {J, 3}, true},
      {"targets/absolute_pose_rot", h5::Type::F32, {J, 3, 3}, true},
      {"targets/world_pose_loc", h5::Type::F32, {J, 3}, true},
      {"targets/world_pose_rot", h5::Type::F32, {J, 3, 3}, true},
      {"targets/world_loc", h5::Type::F32, {3}, false},
      {"targets/world_rot", h5::Type::F32, {3, 3}, false},
      {"targets/velocity", h5::Type::F32, {3}, false},
      {"targets/bboxes", h5::Type::F32, {2, 2}, false},
      {"targets/is_crossing", h5::Type::U8, {}, false},
      {"targets/frame_idx", h5::Type::I64, {}, false},
  };
  return f;
}

// n six-number transforms -> locations (3 each) and CARLA rotation matrices (9 each),
// float32 (the matrices bitwise those of rotation_from_pyr, vector sin/cos).
void split_transforms(const float* t6, std::size_t n, float* loc, float* rot) {
  for (std::size_t j = 0; j < n; ++j)
    loc[3 * j] = t6[6 * j], loc[3 * j + 1] = t6[6 * j + 1], loc[3 * j + 2] = t6[6 * j + 2];
  rotation_matrices_f32(t6, 6, n, rot);
}

// The three 26-joint pose cells of one row (relative, component, world; 156 floats each).
struct PoseCells {
  const float *relative, *component, *world;
};

// Fills frame f of one clip into the per-field buffers at frame slot `s`.
void fill_frame(const PoseTable& t, std::size_t row, const PoseCells& pose,
                std::vector<std::vector<std::uint8_t>>& buf, std::size_t s) {
  auto F = [&](int i) { return reinterpret_cast<float*>(buf[i].data()) + s * frame_fields()[i].per_frame(); };
  std::memcpy(F(0), &t.pose_camera[row * J * 2], sizeof(float) * J * 2);
  split_transforms(pose.relative, J, F(1), F(2));
  split_transforms(pose.component, J, F(3), F(4));
  split_transforms(pose.world, J, F(5), F(6));
  split_transforms(&t.walker_transform[row * 6], 1, F(7), F(8));
  std::memcpy(F(9), &t.velocity[row * 3], sizeof(float) * 3);
  float* bb = F(10);
  const float* uv = &t.pose_camera[row * J * 2];
  float lo_u = INFINITY, lo_v = INFINITY, hi_u = -INFINITY, hi_v = -INFINITY;
  for (int j = 0; j < J; ++j) {
    if (!std::isfinite(uv[2 * j]) || !std::isfinite(uv[2 * j + 1])) continue;
    lo_u = std::min(lo_u, uv[2 * j]), hi_u = std::max(hi_u, uv[2 * j]);
    lo_v = std::min(lo_v, uv[2 * j + 1]), hi_v = std::max(hi_v, uv[2 * j + 1]);
  }
  bb[0] = lo_u, bb[1] = lo_v, bb[2] = hi_u, bb[3] = hi_v;
  buf[11][s] = t.is_crossing[row];
  reinterpret_cast<std::int64_t*>(buf[12].data())[s] = t.frame_idx[row];
}

using Buffers = std::vector<std::vector<std::uint8_t>>;  // one byte buffer per field

// Column indices of the pose cells (kPoseCsvColumns).
constexpr int kWorldColumn = 17, kComponentColumn = 18, kRelativeColumn = 19;

// Fills frame slots [s, s + m) from rows[0..m): the table's pose arrays, or (deferred) the
// rows' pose cells parsed from the file into `scratch` first, a clip's run of rows at once.
void fill_frames(const PoseTable& t, const DeferredCells* cells, const std::size_t* rows,
                 std::size_t m, Buffers& buf, std::size_t s, std::vector<float>& scratch,
                 std::vector<char>& text) {
  if (!cells) {
    for (std::size_t k = 0; k < m; ++k) {
      const std::size_t o = rows[k] * J * 6;
      fill_frame(t, rows[k], {&t.pose_relative[o], &t.pose_component[o], &t.pose_world[o]}, buf,
                 s + k);
    }
    return;
  }
  const std::size_t per_row = cells->floats_per_row();
  scratch.resize(m * per_row);
  cells->read(rows, m, scratch.data(), text);
  for (std::size_t k = 0; k < m; ++k) {
    const float* p = scratch.data() + k * per_row;
    fill_frame(t, rows[k], {p + cells->offset_of(kRelativeColumn), p + cells->offset_of(kComponentColumn),
                            p + cells->offset_of(kWorldColumn)}, buf, s + k);
  }
}

// One task on its own thread; join() rethrows its exception. The destructor joins too (an
// exception of the calling thread must not leave the task running on freed buffers).
class Background {
 public:
  Background() = default;
  Background(const Background&) = delete;
  Background& operator=(const Background&) = delete;
  ~Background() {
    if (thread_.joinable()) thread_.join();
  }
  template <class Fn>
  void run(Fn fn) {
    thread_ = std::thread([this, fn] {
      try {
        fn();
      } catch (...) {
        error_ = std::current_exception();
      }
    });
  }
  void join() {
    if (thread_.joinable()) thread_.join();
    if (error_) std::rethrow_exception(std::exchange(error_, nullptr));
  }

 private:
  std::thread thread_;
  std::exception_ptr error_;
};

// One batch of clips: per field, the filled bytes and (compressed fields) the packed chunks.
struct Batch {
  Buffers raw;
  std::vector<std::vector<std::vector<std::uint8_t>>> packed;  // [field][chunk]
};

// Packs the chunks of the big fields of the first nb clips of `b` (the last one padded with
// zeros to a whole chunk, as libhdf5 stores edge chunks), in parallel.
void pack_chunks(const std::vector<Field>& fields, std::size_t nb, std::size_t rows_per_chunk,
                 std::size_t L, int level, int threads, Batch& b) {
  const std::size_t chunks = (nb + rows_per_chunk - 1) / rows_per_chunk;
  std::vector<std::pair<std::size_t, std::size_t>> jobs;  // (field, chunk)
  for (std::size_t i = 0; i < fields.size(); ++i) {
    b.packed[i].resize(fields[i].big ? chunks : 0);
    for (std::size_t j = 0; fields[i].big && j < chunks; ++j) jobs.emplace_back(i, j);
  }
  parallel_for(jobs.size(), 1, [&](std::size_t lo, std::size_t hi) {
    h5::ChunkPacker packer(level);
    std::vector<std::uint8_t> padded;
    for (std::size_t q = lo; q < hi; ++q) {
      const auto [i, j] = jobs[q];
      const std::size_t clip_bytes = L * fields[i].per_frame() * fields[i].elem();
      const std::size_t rows = std::min(rows_per_chunk, nb - j * rows_per_chunk);
      const std::uint8_t* data = b.raw[i].data() + j * rows_per_chunk * clip_bytes;
      if (rows < rows_per_chunk) {
        padded.assign(rows_per_chunk * clip_bytes, 0);
        std::copy_n(data, rows * clip_bytes, padded.data());
        data = padded.data();
      }
      packer.pack(data, rows_per_chunk * clip_bytes, fields[i].elem(), b.packed[i][j]);
    }
  }, threads);
}

std::string str_at(const StringColumn& c, std::size_t row) {
  return c.values[static_cast<std::size_t>(c.codes[row])];
}

std::string strip_ext(const std::string& p) {
  const auto dot = p.rfind('.'), slash = p.rfind('/');
  return dot == std::string::npos || (slash != std::string::npos && dot < slash) ? p : p.substr(0, dot);
}

}  // namespace

void write_split(const h5::Group& g, const PoseTable& t, const DeferredCells* cells,
                 const Plan& plan, const std::vector<Clip>& clips, int L,
                 const ConvertOptions& opt, ConvertProgress* progress) {
  const hsize_t N = clips.size();
  const h5::Compression none{}, packed{true, opt.compression_level};
  g.create_group("targets");
  const auto& fields = frame_fields();
  std::vector<h5::Handle> ds;
  std::vector<std::vector<hsize_t>> shapes;
  for (const Field& f : fields) {
    std::vector<hsize_t> shape = {N, static_cast<hsize_t>(L)};
    shape.insert(shape.end(), f.tail.begin(), f.tail.end());
    ds.push_back(g.create_dataset(f.name, f.type, shape, static_cast<hsize_t>(opt.chunk_clips),
                                  f.big && opt.compress ? packed : none));
    shapes.push_back(shape);
  }
  // Two sets of batch buffers: with 2+ threads, batch k+1 is filled (in parallel) while
  // this thread hands batch k to libhdf5, whose copies into the page cache are a large
  // part of the conversion. The same values are written in the same order either way.
  // Batches of 2 chunks then (4 otherwise): the buffers take the same memory.
  const std::size_t chunk = static_cast<std::size_t>(std::max(opt.chunk_clips, 1));
  const bool overlap = (opt.threads > 0 ? opt.threads : num_threads()) > 1 && N > 2 * chunk;
  const std::size_t batch = chunk * (overlap ? 2 : 4);
  // With compression, the big fields' chunks are packed (shuffle + deflate) by the worker
  // threads too, and written as stored (write_chunk): libhdf5's filters would run on this
  // one thread. The dataset's chunks hold min(chunk, N) clips; batches start on a chunk.
  const std::size_t rows_per_chunk = std::min<std::size_t>(chunk, N);
  std::array<Batch, 2> bufs;
  for (int k = 0; k < (overlap ? 2 : 1); ++k) {
    bufs[k].raw.resize(fields.size());
    bufs[k].packed.resize(fields.size());
    for (std::size_t i = 0; i < fields.size(); ++i)
      bufs[k].raw[i].resize(batch * static_cast<std::size_t>(L) * fields[i].per_frame() * fields[i].elem());
  }
  const auto fill = [&](std::size_t c0, Batch& buf) {
    const std::size_t nb = std::min<std::size_t>(batch, N - c0);
    const std::size_t Lz = static_cast<std::size_t>(L);
    parallel_for(nb * Lz, 256, [&](std::size_t lo, std::size_t hi) {
      std::vector<float> scratch;
      std::vector<char> text;
      for (std::size_t s = lo; s < hi;) {  // one clip's frames (or the block's part) at a time
        const Clip& c = clips[c0 + s / Lz];
        const std::size_t k = s % Lz, m = std::min(hi - s, Lz - k);
        fill_frames(t, cells, &plan.recordings[c.recording].rows[c.first + k], m, buf.raw, s,
                    scratch, text);
        s += m;
      }
    }, opt.threads);
    if (opt.compress) pack_chunks(fields, nb, rows_per_chunk, static_cast<std::size_t>(L),
                                  opt.compression_level, opt.threads, buf);
  };
  if (N > 0) fill(0, bufs[0]);
  for (std::size_t c0 = 0, k = 0; c0 < N; c0 += batch, k = overlap ? 1 - k : 0) {
    check_cancel(progress);
    const std::size_t nb = std::min<std::size_t>(batch, N - c0), next = c0 + batch;
    Background filling;  // joined before the next batch, and on any exception
    if (overlap && next < N) filling.run([&, next, k] { fill(next, bufs[1 - k]); });
    for (std::size_t i = 0; i < fields.size(); ++i) {
      if (!(fields[i].big && opt.compress)) {
        g.write_rows(ds[i], fields[i].name, fields[i].type, shapes[i], c0, nb, bufs[k].raw[i].data());
        continue;
      }
      std::vector<hsize_t> offset(shapes[i].size(), 0);
      for (std::size_t j = 0; j < bufs[k].packed[i].size(); ++j) {
        offset[0] = c0 + j * rows_per_chunk;
        g.write_chunk(ds[i], fields[i].name, offset, bufs[k].packed[i][j]);
      }
    }
    filling.join();
    if (next < N && !overlap) fill(next, bufs[0]);
    if (progress) progress->done += nb;
  }
  write_clip_meta(g, t, plan, clips, L);
}

void write_clip_meta(const h5::Group& g, const PoseTable& t, const Plan& plan,
                     const std::vector<Clip>& clips, int L) {
  const std::size_t N = clips.size();
  std::vector<std::string> video(N), ped(N), age(N), gender(N), model(N), map(N);
  std::vector<std::int32_t> clip_id(N), segment(N), tte(N);
  std::vector<std::int64_t> start(N), end(N), width(N), height(N);
  std::vector<std::uint8_t> label(N);
  std::vector<float> cam(N * 6);
  for (std::size_t i = 0; i < N; ++i) {
    const Clip& c = clips[i];
    const Recording& rec = plan.recordings[c.recording];
    const std::size_t first = rec.rows[c.first], last = rec.rows[c.first + static_cast<std::size_t>(L) - 1];
    video[i] = strip_ext(str_at(t.recording, first));
    ped[i] = std::to_string(rec.camera_idx) + "_" + std::to_string(rec.pedestrian_idx);
    age[i] = str_at(t.age, first), gender[i] = str_at(t.gender, first);
    model[i] = str_at(t.model, first), map[i] = str_at(t.map, first);
    clip_id[i] = c.index, segment[i] = c.segment, label[i] = c.label, tte[i] = c.time_to_event;
    start[i] = t.frame_idx[first], end[i] = t.frame_idx[last] + 1;
    width[i] = t.camera_width[first], height[i] = t.camera_height[first];
    std::copy_n(&t.camera_transform[first * 6], 6, &cam[i * 6]);
  }
  const h5::Compression none{};
  auto put = [&](const std::string& name, h5::Type type, std::vector<hsize_t> shape, const void* d) {
    auto h = g.create_dataset(name, type, shape, 4096, none);
    g.write_rows(h, name, type, shape, 0, shape[0], d);
  };
  put("labels", h5::Type::U8, {N}, label.data());
  const h5::Group m = g.create_group("meta");
  m.write_strings("video_id", video);
  m.write_strings("pedestrian_id", ped);
  m.write_strings("age", age);
  m.write_strings("gender", gender);
  m.write_strings("model", model);
  m.write_strings("map", map);
  auto put_m = [&](const std::string& name, h5::Type type, std::vector<hsize_t> shape, const void* d) {
    auto h = m.create_dataset(name, type, shape, 4096, none);
    m.write_rows(h, name, type, shape, 0, shape[0], d);
  };
  put_m("clip_id", h5::Type::I32, {N}, clip_id.data());
  put_m("segment", h5::Type::I32, {N}, segment.data());
  put_m("start_frame", h5::Type::I64, {N}, start.data());
  put_m("end_frame", h5::Type::I64, {N}, end.data());
  put_m("clip_width", h5::Type::I64, {N}, width.data());
  put_m("clip_height", h5::Type::I64, {N}, height.data());
  put_m("camera_transform", h5::Type::F32, {N, 6}, cam.data());
  put_m("tte", h5::Type::I32, {N}, tte.data());  // kNoEvent (-1) outside benchmark mode
}

}  // namespace bsp::detail
