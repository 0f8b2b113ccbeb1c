#include "domains/franka/offscreen_renderer.h"

#include <GL/osmesa.h>

#include <cstring>
#include <vector>

#include "domains/franka/mujoco_model.h"
#include "secure/common/error.h"

namespace secure::domains::franka {

struct OffscreenRenderer::Impl {
  std::string who;
  OSMesaContext gl = nullptr;
  std::vector<unsigned char> buffer;  // the OSMesa colour buffer (RGBA)
  mjvScene scene;
  mjvCamera camera;
  mjvOption option;
  mjrContext context;
  std::vector<unsigned char> rows;  // bottom-up RGB from mjr_readPixels

  void MakeCurrent() {
    SECURE_CHECK(
        OSMesaMakeCurrent(gl, buffer.data(), GL_UNSIGNED_BYTE, kMaxRenderWidth, kMaxRenderHeight),
        who << " renderer: OSMesaMakeCurrent failed");
  }
};

OffscreenRenderer::OffscreenRenderer(const mjModel* m, const CameraView& view,
                                     const std::string& who)
    : impl_(std::make_unique<Impl>()) {
  InstallMujocoHandlers();
  Impl& r = *impl_;
  r.who = who;
  SECURE_CHECK(
      m->vis.global.offwidth >= kMaxRenderWidth && m->vis.global.offheight >= kMaxRenderHeight,
      who << " renderer: the model's offscreen buffer is " << m->vis.global.offwidth << " x "
          << m->vis.global.offheight << ", smaller than " << kMaxRenderWidth << " x "
          << kMaxRenderHeight);
  r.gl = OSMesaCreateContextExt(OSMESA_RGBA, 24, 8, 0, nullptr);
  SECURE_CHECK(r.gl != nullptr, who << " renderer: cannot create an OSMesa context");
  r.buffer.assign(static_cast<size_t>(kMaxRenderWidth) * kMaxRenderHeight * 4, 0);
  r.MakeCurrent();
  mjv_defaultScene(&r.scene);
  mjv_defaultCamera(&r.camera);
  mjv_defaultOption(&r.option);
  mjr_defaultContext(&r.context);
  mjv_makeScene(m, &r.scene, 2000);
  mjr_makeContext(m, &r.context, mjFONTSCALE_100);
  mjr_setBuffer(mjFB_OFFSCREEN, &r.context);
  SECURE_CHECK(r.context.currentBuffer == mjFB_OFFSCREEN,
               who << " renderer: no offscreen framebuffer in this OpenGL context");
  r.camera.type = mjCAMERA_FREE;
  for (int k = 0; k < 3; ++k) r.camera.lookat[k] = view.lookat[k];
  r.camera.distance = view.distance;
  r.camera.azimuth = view.azimuth;
  r.camera.elevation = view.elevation;
}

OffscreenRenderer::~OffscreenRenderer() {
  Impl& r = *impl_;
  if (r.gl != nullptr) {
    OSMesaMakeCurrent(r.gl, r.buffer.data(), GL_UNSIGNED_BYTE, kMaxRenderWidth, kMaxRenderHeight);
    mjr_freeContext(&r.context);
    mjv_freeScene(&r.scene);
    OSMesaDestroyContext(r.gl);
  }
}

void OffscreenRenderer::Render(const mjModel* m, mjData* d, int width, int height, Frame* frame) {
  Impl& r = *impl_;
  SECURE_CHECK(width >= 2 && width <= kMaxRenderWidth && height >= 2 && height <= kMaxRenderHeight,
               r.who << ": frame size " << width << " x " << height << " is outside [2, "
                     << kMaxRenderWidth << "] x [2, " << kMaxRenderHeight << "]");
  r.MakeCurrent();
  mjv_updateScene(m, d, &r.option, nullptr, &r.camera, mjCAT_ALL, &r.scene);
  const mjrRect viewport = {0, 0, width, height};
  mjr_render(viewport, &r.scene, &r.context);
  r.rows.resize(static_cast<size_t>(3) * width * height);
  mjr_readPixels(r.rows.data(), nullptr, viewport, &r.context);
  // OpenGL rows are bottom-up.
  frame->width = width;
  frame->height = height;
  frame->rgb.resize(r.rows.size());
  const size_t stride = static_cast<size_t>(3) * width;
  for (int y = 0; y < height; ++y)
    std::memcpy(frame->rgb.data() + stride * y, r.rows.data() + stride * (height - 1 - y), stride);
}

void RenderSimulation(std::unique_ptr<OffscreenRenderer>* renderer, const void* model, void* data,
                      const CameraView& view, const char* who, int width, int height,
                      Frame* frame) {
  const auto* m = static_cast<const mjModel*>(model);
  if (*renderer == nullptr) *renderer = std::make_unique<OffscreenRenderer>(m, view, who);
  (*renderer)->Render(m, static_cast<mjData*>(data), width, height, frame);
}

}  // namespace secure::domains::franka
