// secure.Overlay (the overlay `secure render` draws: step, h(s), the shield's status,
// interventions, a plot of h) and secure.VideoWriter (frames to an MP4 through ffmpeg, as
// `secure render --out` writes them).
#include <cstring>
#include <memory>
#include <optional>
#include <string>

#include "common.h"
#include "python/src/guard.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/eval/overlay.h"
#include "secure/eval/video.h"

namespace secure::python {
namespace {

SECURE_PYTHON_TYPE(FrameArray, "numpy.typing.NDArray[numpy.uint8]");
SECURE_PYTHON_TYPE(OptionalAny, "Optional[Any]");

// A (height, width, 3) uint8 array as a Frame (copied). TypeError for another dtype, ValueError
// for another shape.
domains::Frame FrameOf(const py::handle& object, const char* what) {
  if (!py::isinstance<py::array>(object) ||
      !py::array(py::reinterpret_borrow<py::object>(object)).dtype().is(py::dtype::of<std::uint8_t>())) {
    throw py::type_error(std::string(what) + ": expected a (height, width, 3) numpy.uint8 array, got " +
                         std::string(py::str(py::type::of(object).attr("__name__"))) +
                         (py::isinstance<py::array>(object)
                              ? " of dtype " + std::string(py::str(py::array(
                                                   py::reinterpret_borrow<py::object>(object))
                                                                      .dtype()))
                              : std::string()));
  }
  const auto array = py::array_t<std::uint8_t, py::array::c_style | py::array::forcecast>::ensure(object);
  if (array.ndim() != 3 || array.shape(2) != 3) {
    std::string shape = "(";
    for (py::ssize_t i = 0; i < array.ndim(); ++i) shape += (i ? ", " : "") + std::to_string(array.shape(i));
    throw py::value_error(std::string(what) + ": expected shape (height, width, 3), got " + shape +
                          (array.ndim() == 1 ? ",)" : ")"));
  }
  domains::Frame frame;
  frame.height = static_cast<int>(array.shape(0));
  frame.width = static_cast<int>(array.shape(1));
  frame.rgb.resize(static_cast<std::size_t>(array.size()));
  if (!frame.rgb.empty()) std::memcpy(frame.rgb.data(), array.data(), frame.rgb.size());
  return frame;
}

py::array_t<std::uint8_t> ArrayOf(const domains::Frame& frame) {
  py::array_t<std::uint8_t> out({frame.height, frame.width, 3});
  std::memcpy(out.mutable_data(), frame.rgb.data(), frame.rgb.size());
  return out;
}

class Overlay {
 public:
  Overlay(const std::string& title, int max_steps, bool panel)
      : overlay_(eval::OverlayOptions{title, max_steps, panel}) {}

  py::array_t<std::uint8_t> Draw(FrameArray frame, long step, std::optional<double> h,
                                 const std::string& status, bool intervened, bool collided,
                                 bool reached_goal) {
    if (!status.empty()) FromString(shield::kStatusNames, status, "status ('' unshielded)");
    domains::Frame f = FrameOf(frame, "frame");
    eval::OverlayStep s;
    s.step = step;
    s.h = h;
    s.status = status;
    s.intervened = intervened;
    s.collided = collided;
    s.reached_goal = reached_goal;
    overlay_.Draw(s, f);
    return ArrayOf(f);
  }
  void Reset() { overlay_.Reset(); }

 private:
  eval::EpisodeOverlay overlay_;
};

class VideoWriter {
 public:
  VideoWriter(const std::string& path, int width, int height, int fps)
      : writer_(std::make_unique<eval::VideoWriter>(path, eval::VideoOptions{width, height, fps})) {}

  void Write(FrameArray frame) {
    Open().Write(FrameOf(frame, "frame"));
  }
  void Finish() {
    Open().Finish();
    path_ = writer_->path();
    frames_ = writer_->frames();
    writer_.reset();
  }
  // Without Finish(): stops ffmpeg, removes the scratch file, leaves the path as it was.
  void Discard() { writer_.reset(); }
  long frames() const { return writer_ ? writer_->frames() : frames_; }
  bool finished() const { return !writer_; }

 private:
  eval::VideoWriter& Open() {
    if (!writer_) throw std::runtime_error("VideoWriter: finished or discarded (make a new one)");
    return *writer_;
  }
  std::unique_ptr<eval::VideoWriter> writer_;
  std::string path_;
  long frames_ = 0;
};

}  // namespace
}  // namespace secure::python
// An Overlay or VideoWriter made by __new__ without __init__ is a TypeError, not a crash.
SECURE_PYTHON_CHECK_INITIALISED(secure::python::Overlay);
SECURE_PYTHON_CHECK_INITIALISED(secure::python::VideoWriter);
namespace secure::python {

void RegisterRender(py::module_& m) {
  py::class_<Overlay>(m, "Overlay", R"doc(
The overlay `secure render` draws into an episode's frames: a band at the top with the title, the
step, h(s) and the shield's status for the action that led to the state; an orange border where
the shield intervened and a red one where it found no safe action or the state is dangerous; and a
panel at the bottom plotting h over the episode so far (h = 0 dashed, interventions as orange
ticks, collisions as red dots). Draw the frames of one episode in order; a step at or below the
last one drawn starts a new episode.

    overlay = secure.Overlay(title="SECURE", max_steps=env.max_steps)
    frame = overlay.draw(env.render(), step=t, h=d.h, status=d.status, intervened=d.intervened))doc")
      .def(py::init<const std::string&, int, bool>(), py::arg("title") = "",
           py::arg("max_steps") = 0, py::arg("panel") = true,
           "title: the band's first words; max_steps: the panel's time axis (at least); panel: "
           "draw the plot of h.")
      .def("draw", &Overlay::Draw, py::arg("frame"), py::kw_only(), py::arg("step"),
           py::arg("h") = py::none(), py::arg("status") = "", py::arg("intervened") = false,
           py::arg("collided") = false, py::arg("reached_goal") = false,
           "A copy of `frame` ((height, width, 3) uint8, at least 64 x 48) with the overlay for "
           "this step: h of the state shown (None: unknown), the shield's status for the last "
           "action ('' unshielded, else a Decision.status).")
      .def("reset", &Overlay::Reset, "Forget the plotted history (a new episode).");

  py::class_<VideoWriter>(m, "VideoWriter", R"doc(
Frames to an MP4 video (H.264 through the ffmpeg program, as `secure render --out`): the file
appears only when finish() succeeds; until then an existing file at `path` is left as it was. As a
context manager it finishes on a normal exit and discards the video on an exception.

    with secure.VideoWriter("episode.mp4", 640, 480, fps=20) as video:
        video.write(frame)  # (480, 640, 3) uint8)doc")
      .def(py::init<const std::string&, int, int, int>(), py::arg("path"), py::arg("width"),
           py::arg("height"), py::arg("fps") = 20,
           "Starts ffmpeg. width and height even; fps 1 to 1000. Raises ValueError naming what is "
           "wrong (e.g. ffmpeg not found, `path` a directory).")
      .def("write", &VideoWriter::Write, py::arg("frame"),
           "Encodes one (height, width, 3) uint8 frame of the video's size.")
      .def("finish", &VideoWriter::Finish, "Ends the stream and installs the video at `path`.")
      .def("discard", &VideoWriter::Discard,
           "Stops without writing the video (the scratch file is removed).")
      .def_property_readonly("frames", &VideoWriter::frames, "Frames written so far.")
      .def_property_readonly("finished", &VideoWriter::finished,
                             "finish() or discard() was called.")
      .def("__enter__", [](VideoWriter& v) -> VideoWriter& { return v; },
           py::return_value_policy::reference)
      .def("__exit__",
           [](VideoWriter& v, const OptionalAny& type, const OptionalAny&, const OptionalAny&) {
             if (v.finished()) return false;
             if (type.is_none()) {
               v.Finish();
             } else {
               v.Discard();
             }
             return false;
           },
           py::arg("exc_type"), py::arg("exc_value"), py::arg("traceback"));
}

}  // namespace secure::python
