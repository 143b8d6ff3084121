// The software rasteriser's loops (raster.cpp); bindings/render.cpp checks the arrays' shapes.
#pragma once

#include <cstdint>

#include "config.hpp"

namespace softbody::render {

struct Image {
    double* rgb = nullptr;      // (H, W, 3) in [0, 1]
    double* zbuffer = nullptr;  // (H, W) 1 / depth [1/m], 0 = infinitely far
    index height = 0, width = 0;
};

/// A vertical gradient top -> bottom (3,) and an empty depth buffer.
void clear(const Image& im, const double* top, const double* bottom);
/// Triangles faces (F, 3) of points screen (V, 3) (x, y [px], depth [m]) with per-vertex
/// colours (V, 3), depth-tested, perspective-correct; any corner nearer than `near` [m]
/// skips the triangle.
void triangles(const Image& im, const double* screen, const index* faces, index face_count,
               const double* colors, double near);
/// Segments screen_a -> screen_b (L, 3), colours (L, 3), `width` [px] wide, drawn where no
/// farther than the surface there, with a relative depth bias.
void lines(const Image& im, const double* screen_a, const double* screen_b, index line_count,
           const double* colors, index width, double near, double depth_bias);
/// Average factor x factor blocks into out (out_height, out_width, 3) uint8.
void downsample(const Image& im, index factor, std::uint8_t* out, index out_height,
                index out_width);

}  // namespace softbody::render
