#include "secure/eval/render.h"

#include <memory>

#include "secure/cbf/barrier.h"
#include "secure/common/error.h"

namespace secure::eval {
namespace {

class FrameObserver final : public StepObserver {
 public:
  FrameObserver(domains::Environment& env, int width, int height,
                std::unique_ptr<cbf::Barrier> barrier,
                const std::function<void(domains::Frame&, const FrameInfo&)>& on_frame)
      : env_(env),
        width_(width),
        height_(height),
        barrier_(std::move(barrier)),
        on_frame_(on_frame) {}
  void OnEpisodeStart(long /*episode*/, const Eigen::VectorXf& observation) override {
    FrameInfo info;
    info.h = H(observation);
    Draw(info);
  }
  void OnStep(const StepView& step) override {
    FrameInfo info;
    info.step = step.step + 1;
    info.h = H(step.observation);
    info.decision = step.decision;
    info.collided = step.outcome.collided;
    info.reached_goal = step.outcome.reached_goal;
    Draw(info);
  }
  long frames() const { return frames_; }

 private:
  std::optional<double> H(const Eigen::VectorXf& observation) {
    if (!barrier_) return std::nullopt;
    Eigen::VectorXf h(1);
    barrier_->Evaluate(observation, h);
    return static_cast<double>(h[0]);
  }
  void Draw(const FrameInfo& info) {
    env_.Render(width_, height_, &frame_);
    SECURE_CHECK(frame_.width == width_ && frame_.height == height_ &&
                     frame_.rgb.size() ==
                         3 * static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_),
                 "Render(" << width_ << ", " << height_ << ") of '" << env_.Describe()
                           << "' gave a " << frame_.width << " x " << frame_.height << " frame of "
                           << frame_.rgb.size() << " bytes");
    on_frame_(frame_, info);
    ++frames_;
  }

  domains::Environment& env_;
  int width_, height_;
  std::unique_ptr<cbf::Barrier> barrier_;
  const std::function<void(domains::Frame&, const FrameInfo&)>& on_frame_;
  domains::Frame frame_;
  long frames_ = 0;
};

}  // namespace

RenderedEpisode RenderEpisode(domains::Environment& env, Method method, const SeedModels& models,
                              const shield::ShieldOptions& shield_options, std::uint64_t seed,
                              long episode, int width, int height,
                              const std::function<void(const domains::Frame&)>& on_frame) {
  return RenderEpisode(env, method, models, shield_options, seed, episode, width, height,
                       [&](domains::Frame& frame, const FrameInfo&) { on_frame(frame); });
}

RenderedEpisode RenderEpisode(domains::Environment& env, Method method, const SeedModels& models,
                              const shield::ShieldOptions& shield_options, std::uint64_t seed,
                              long episode, int width, int height,
                              const std::function<void(domains::Frame&, const FrameInfo&)>& on_frame) {
  SECURE_CHECK(env.CanRender(),
               "the environment cannot render (no offscreen renderer): " << env.Describe());
  SECURE_CHECK(width > 0 && height > 0,
               "RenderEpisode: frame size " << width << " x " << height << ", must be positive");
  SECURE_CHECK(episode >= 0, "RenderEpisode: episode = " << episode << ", must be >= 0");
  EpisodeRunnerOptions options;
  options.first_episode = episode;
  EpisodeRunner runner(env, options);
  FrameObserver observer(env, width, height,
                         models.make_barrier ? models.make_barrier() : nullptr, on_frame);
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
