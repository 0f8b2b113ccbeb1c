#include "secure/eval/render.h"

#include "secure/common/error.h"

namespace secure::eval {
namespace {

class FrameObserver final : public StepObserver {
 public:
  FrameObserver(domains::Environment& env, int width, int height,
                const std::function<void(const domains::Frame&)>& on_frame)
      : env_(env), width_(width), height_(height), on_frame_(on_frame) {}
  void OnEpisodeStart(long /*episode*/, const Eigen::VectorXf& /*observation*/) override { Draw(); }
  void OnStep(const StepView& /*step*/) override { Draw(); }
  long frames() const { return frames_; }

 private:
  void Draw() {
    env_.Render(width_, height_, &frame_);
    SECURE_CHECK(frame_.width == width_ && frame_.height == height_ &&
                     frame_.rgb.size() ==
                         3 * static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_),
                 "Render(" << width_ << ", " << height_ << ") of '" << env_.Describe()
                           << "' gave a " << frame_.width << " x " << frame_.height << " frame of "
                           << frame_.rgb.size() << " bytes");
    on_frame_(frame_);
    ++frames_;
  }

  domains::Environment& env_;
  int width_, height_;
  const std::function<void(const domains::Frame&)>& on_frame_;
  domains::Frame frame_;
  long frames_ = 0;
};

}  // namespace

RenderedEpisode RenderEpisode(domains::Environment& env, Method method, const SeedModels& models,
                              const shield::ShieldOptions& shield_options, std::uint64_t seed,
                              long episode, int width, int height,
                              const std::function<void(const domains::Frame&)>& on_frame) {
  SECURE_CHECK(env.CanRender(),
               "the environment cannot render (no offscreen renderer): " << env.Describe());
  SECURE_CHECK(width > 0 && height > 0,
               "RenderEpisode: frame size " << width << " x " << height << ", must be positive");
  SECURE_CHECK(episode >= 0, "RenderEpisode: episode = " << episode << ", must be >= 0");
  EpisodeRunnerOptions options;
  options.first_episode = episode;
  EpisodeRunner runner(env, options);
  FrameObserver observer(env, width, height, on_frame);
  const SeedResult r = RunMethod(runner, method, models, shield_options, 1, seed, &observer);
  RenderedEpisode out;
  out.frames = observer.frames();
  out.steps = r.steps;
  out.success = r.successes > 0;
  out.dangerous = r.dangerous > 0;
  out.collision_events = r.collision_events;
  return out;
}

}  // namespace secure::eval
