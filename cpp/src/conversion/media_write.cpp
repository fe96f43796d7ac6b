// The media pipeline of one split: worker threads take recordings from an atomic index and
// decode each into a block of the frame table; the one thread that owns the HDF5 file
// (libhdf5 is not thread-safe) writes the blocks in table order, in whole chunks. Table
// positions are fixed before decoding starts, so the file does not depend on timing.
#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <cstring>
#include <mutex>
#include <optional>
#include <thread>

#include "bsp/common/parallel.hpp"
#include "convert_internal.hpp"

namespace bsp::detail {
namespace {

constexpr hsize_t kSmallChunk = 1024;  // frames per chunk of the per-frame numbers

// Workers claim block numbers in order and may start block b only while
// b < taken + window, so at most `window` blocks are being decoded or wait to be written,
// plus the one being written: memory is bounded by the thread count.
class BlockQueue {
 public:
  BlockQueue(std::size_t n, std::size_t window) : slots_(n), window_(window) {}
  std::size_t size() const { return slots_.size(); }

  // The next block to decode, or size() when all are claimed or the queue stopped.
  std::size_t claim() {
    const std::size_t b = next_++;
    if (b >= slots_.size()) return slots_.size();
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return stop_ || b < taken_ + window_; });
    return stop_ ? slots_.size() : b;
  }
  void put(std::size_t b, MediaBlock block) {
    std::lock_guard<std::mutex> lock(mu_);
    slots_[b] = std::move(block);
    cv_.notify_all();
  }
  // Blocks are taken in order 0, 1, ...
  MediaBlock take(std::size_t b) {
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return slots_[b].has_value(); });
    MediaBlock out = std::move(*slots_[b]);
    slots_[b].reset();
    taken_ = b + 1;
    cv_.notify_all();
    return out;
  }
  void stop() {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
    cv_.notify_all();
  }

 private:
  std::vector<std::optional<MediaBlock>> slots_;
  std::size_t window_, taken_ = 0;
  std::atomic<std::size_t> next_{0};
  bool stop_ = false;
  std::mutex mu_;
  std::condition_variable cv_;
};

// Stages rows of each frames/* dataset until a whole chunk can be written at once, so no
// chunk is ever written twice (a partial write of a compressed chunk means reading,
// inflating and deflating it again).
class FrameTableWriter {
 public:
  FrameTableWriter(const h5::Group& g, std::size_t frames, const MediaOptions& o) : g_(g) {
    for (FrameColumn& c : frame_columns(o)) {
      Column col;
      col.spec = std::move(c);
      const bool rgb = col.spec.name == "frames/rgb" || col.spec.name == "frames/context_rgb";
      const bool mask = col.spec.name == "frames/mask";
      const int level = rgb ? o.rgb_level : mask ? o.mask_level : 0;
      // Deflated RGB goes in one-frame chunks: a random clip then inflates only its frames.
      col.chunk = rgb && level > 0 ? 1
                  : rgb || mask    ? static_cast<hsize_t>(std::max(o.chunk_frames, 1))
                                   : kSmallChunk;
      col.shape = {frames};
      col.shape.insert(col.shape.end(), col.spec.tail.begin(), col.spec.tail.end());
      col.ds = g.create_dataset(col.spec.name, col.spec.type, col.shape, col.chunk,
                                h5::Compression{level > 0, level});
      col.stage.resize(std::min<std::size_t>(col.chunk, frames) * col.spec.bytes);
      cols_.push_back(std::move(col));
    }
  }
  void append(const MediaBlock& b) {
    for (std::size_t c = 0; c < cols_.size(); ++c) {
      Column& col = cols_[c];
      for (std::size_t done = 0; done < b.frames;) {
        const std::size_t n = std::min<std::size_t>(b.frames - done, col.chunk - col.staged);
        std::memcpy(col.stage.data() + col.staged * col.spec.bytes,
                    b.cols[c].data() + done * col.spec.bytes, n * col.spec.bytes);
        col.staged += n, done += n;
        if (col.staged == col.chunk) flush(col);
      }
    }
  }
  void finish() {
    for (Column& col : cols_)
      if (col.staged) flush(col);
  }

 private:
  struct Column {
    FrameColumn spec;
    hsize_t chunk = 1;
    std::vector<hsize_t> shape;
    h5::Handle ds;
    std::vector<std::uint8_t> stage;
    std::size_t staged = 0, written = 0;
  };
  void flush(Column& col) {
    g_.write_rows(col.ds, col.spec.name, col.spec.type, col.shape, col.written, col.staged,
                  col.stage.data());
    col.written += col.staged;
    col.staged = 0;
  }
  const h5::Group& g_;
  std::vector<Column> cols_;
};

void write_clip_frames(const h5::Group& g, const FrameTable& table, int L, int chunk_clips) {
  const std::vector<hsize_t> shape = {table.clip_frames.size() / static_cast<std::size_t>(L),
                                      static_cast<hsize_t>(L)};
  const h5::Handle ds = g.create_dataset("clip_frames", h5::Type::I64, shape,
                                         static_cast<hsize_t>(chunk_clips), h5::Compression{});
  g.write_rows(ds, "clip_frames", h5::Type::I64, shape, 0, shape[0], table.clip_frames.data());
}

// Stops the queue and joins the workers however the writer leaves.
struct Workers {
  BlockQueue& queue;
  std::vector<std::thread> pool;
  ~Workers() {
    queue.stop();
    for (auto& th : pool)
      if (th.joinable()) th.join();
  }
};

}  // namespace

std::vector<MediaFailure> write_media(const std::array<const h5::Group*, 3>& groups,
                                      const PoseTable& t, const std::array<FrameTable, 3>& tables,
                                      const std::vector<MediaFiles>& files,
                                      const ConvertOptions& opt, ConvertProgress* progress,
                                      std::array<std::size_t, 3>& occluded) {
  occluded = {};
  std::array<std::optional<FrameTableWriter>, 3> writers;
  // One queue over the blocks of all splits, so no split's tail leaves threads idle.
  std::vector<std::pair<int, std::size_t>> blocks;  // (split, block)
  for (int s = 0; s < 3; ++s) {
    const FrameTable& ft = tables[static_cast<std::size_t>(s)];
    for (std::size_t b = 0; b < ft.recordings.size(); ++b) blocks.emplace_back(s, b);
    if (!groups[static_cast<std::size_t>(s)]) continue;
    const h5::Group& g = *groups[static_cast<std::size_t>(s)];
    write_clip_frames(g, ft, opt.clips.length, opt.chunk_clips);
    g.create_group("frames");
    writers[static_cast<std::size_t>(s)].emplace(g, ft.frames(), opt.media);
  }
  const std::size_t threads = std::min<std::size_t>(
      static_cast<std::size_t>(opt.threads > 0 ? opt.threads : num_threads()), blocks.size());
  BlockQueue queue(blocks.size(), threads + 1);
  Workers workers{queue, {}};
  auto decode = [&](std::size_t i) {
    const FrameTable& ft = tables[static_cast<std::size_t>(blocks[i].first)];
    const std::size_t b = blocks[i].second;
    try {
      check_cancel(progress);  // a failure without a path: never skipped, always rethrown
      return decode_block(t, ft, b, files[ft.recordings[b]], opt.media, progress);
    } catch (...) {  // e.g. bad_alloc before decoding started
      MediaBlock failed;
      failed.failure.recording = ft.recordings[b];
      failed.failure.reason = "cannot allocate the block";
      failed.failure.error = std::current_exception();
      return failed;
    }
  };
  for (std::size_t i = 0; i < threads; ++i)
    workers.pool.emplace_back([&] {
      for (std::size_t b; (b = queue.claim()) < queue.size();) queue.put(b, decode(b));
    });
  std::vector<MediaFailure> failures;
  for (std::size_t i = 0; i < blocks.size(); ++i) {
    MediaBlock block = queue.take(i);
    check_cancel(progress);
    if (block.failure.error) {
      // Only media errors may be skipped (decode_block names the file before opening it).
      if (!opt.media.skip_bad_media || block.failure.path.empty())
        std::rethrow_exception(block.failure.error);
      failures.push_back(std::move(block.failure));
      for (auto& w : writers) w.reset();  // the pass is redone without it: stop writing
    } else if (auto& w = writers[static_cast<std::size_t>(blocks[i].first)]) {
      w->append(block);
      for (std::size_t f = 0; f < block.frames; ++f)
        occluded[static_cast<std::size_t>(blocks[i].first)] += *block.at<std::int64_t>(kColPixels, f) == 0;
    }
  }
  for (auto& w : writers)
    if (w) w->finish();
  return failures;
}

}  // namespace bsp::detail
