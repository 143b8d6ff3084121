// A small z-buffered software rasteriser: triangles and lines into an RGB image (float64,
// H x W x 3, values in [0, 1]) with a depth buffer of 1/depth (0 is infinitely far, and
// 1/z interpolates linearly in screen space), then averaged down to 8-bit RGB. The Python
// side (softbody.render) plans the frame; these loops fill it. Coordinates that are not
// finite, or far off the image, draw nothing (never an out-of-range conversion).
#include "render/raster.hpp"

#include <algorithm>
#include <cmath>

namespace softbody::render {

void clear(const Image& im, const double* top, const double* bottom) {
    for (index y = 0; y < im.height; ++y) {
        const double w = static_cast<double>(y) / static_cast<double>(std::max<index>(im.height - 1, 1));
        for (index x = 0; x < im.width; ++x) {
            im.zbuffer[y * im.width + x] = 0.0;
            for (int k = 0; k < 3; ++k)
                im.rgb[3 * (y * im.width + x) + k] = top[k] * (1.0 - w) + bottom[k] * w;
        }
    }
}

namespace {

/// floor(v) clamped to [lo, hi] as an index (v finite).
index clamp_index(double v, index lo, index hi) {
    return static_cast<index>(std::min(std::max(v, static_cast<double>(lo)), static_cast<double>(hi)));
}

}  // namespace

void triangles(const Image& im, const double* screen, const index* faces, index face_count,
               const double* colors, double near) {
    const index h = im.height, w = im.width;
    for (index t = 0; t < face_count; ++t) {
        const index i = faces[3 * t], j = faces[3 * t + 1], k = faces[3 * t + 2];
        const double z0 = screen[3 * i + 2], z1 = screen[3 * j + 2], z2 = screen[3 * k + 2];
        if (z0 < near || z1 < near || z2 < near) continue;
        const double x0 = screen[3 * i], y0 = screen[3 * i + 1];
        const double x1 = screen[3 * j], y1 = screen[3 * j + 1];
        const double x2 = screen[3 * k], y2 = screen[3 * k + 1];
        if (!(std::isfinite(x0) && std::isfinite(y0) && std::isfinite(x1) && std::isfinite(y1) &&
              std::isfinite(x2) && std::isfinite(y2)))
            continue;
        const double area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0);
        if (area == 0.0) continue;
        const index xmin = clamp_index(std::floor(std::min({x0, x1, x2})), 0, w);
        const index xmax = clamp_index(std::ceil(std::max({x0, x1, x2})), -1, w - 1);
        const index ymin = clamp_index(std::floor(std::min({y0, y1, y2})), 0, h);
        const index ymax = clamp_index(std::ceil(std::max({y0, y1, y2})), -1, h - 1);
        const double inv_area = 1.0 / area;
        const double iz0 = 1.0 / z0, iz1 = 1.0 / z1, iz2 = 1.0 / z2;
        for (index py = ymin; py <= ymax; ++py) {
            const double cy = static_cast<double>(py) + 0.5;
            for (index px = xmin; px <= xmax; ++px) {
                const double cx = static_cast<double>(px) + 0.5;
                const double b0 = ((x1 - cx) * (y2 - cy) - (x2 - cx) * (y1 - cy)) * inv_area;
                const double b1 = ((x2 - cx) * (y0 - cy) - (x0 - cx) * (y2 - cy)) * inv_area;
                const double b2 = 1.0 - b0 - b1;
                if (b0 < 0.0 || b1 < 0.0 || b2 < 0.0) continue;
                const double iz = b0 * iz0 + b1 * iz1 + b2 * iz2;
                double& depth = im.zbuffer[py * w + px];
                if (iz <= depth) continue;
                depth = iz;
                // perspective-correct colour weights
                const double w0 = b0 * iz0 / iz, w1 = b1 * iz1 / iz, w2 = b2 * iz2 / iz;
                for (int c = 0; c < 3; ++c)
                    im.rgb[3 * (py * w + px) + c] =
                        w0 * colors[3 * i + c] + w1 * colors[3 * j + c] + w2 * colors[3 * k + c];
            }
        }
    }
}

void lines(const Image& im, const double* screen_a, const double* screen_b, index line_count,
           const double* colors, index width, double near, double depth_bias) {
    const index h = im.height, w = im.width;
    const index half = width / 2;
    for (index s = 0; s < line_count; ++s) {
        const double za = screen_a[3 * s + 2], zb = screen_b[3 * s + 2];
        if (za < near || zb < near) continue;
        const double xa = screen_a[3 * s], ya = screen_a[3 * s + 1];
        const double xb = screen_b[3 * s], yb = screen_b[3 * s + 1];
        const double span = std::max(std::fabs(xb - xa), std::fabs(yb - ya));
        // absurdly long (an end point near the camera plane), or not finite: nothing
        if (!(span < 4.0 * static_cast<double>(w + h))) continue;
        const index n = static_cast<index>(span) + 1;
        const double iza = 1.0 / za, izb = 1.0 / zb;
        for (index k = 0; k <= n; ++k) {
            const double u = static_cast<double>(k) / static_cast<double>(n);
            const double fx = xa + u * (xb - xa), fy = ya + u * (yb - ya);
            if (!(std::fabs(fx) < 1e9 && std::fabs(fy) < 1e9)) continue;  // off the image
            const index x = static_cast<index>(fx), y = static_cast<index>(fy);
            const double iz = iza + u * (izb - iza);
            for (index dy = -half; dy < width - half; ++dy)
                for (index dx = -half; dx < width - half; ++dx) {
                    const index px = x + dx, py = y + dy;
                    if (px < 0 || py < 0 || px >= w || py >= h) continue;
                    double& depth = im.zbuffer[py * w + px];
                    if (iz * (1.0 + depth_bias) < depth) continue;
                    depth = std::max(depth, iz);
                    for (int c = 0; c < 3; ++c) im.rgb[3 * (py * w + px) + c] = colors[3 * s + c];
                }
        }
    }
}

void downsample(const Image& im, index factor, std::uint8_t* out, index out_height,
                index out_width) {
    for (index y = 0; y < out_height; ++y)
        for (index x = 0; x < out_width; ++x)
            for (int c = 0; c < 3; ++c) {
                double acc = 0.0;
                for (index dy = 0; dy < factor; ++dy)
                    for (index dx = 0; dx < factor; ++dx)
                        acc += im.rgb[3 * ((y * factor + dy) * im.width + x * factor + dx) + c];
                const double v = acc / static_cast<double>(factor * factor) * 255.0 + 0.5;
                const double clamped = v > 0.0 ? std::min(v, 255.0) : 0.0;  // NaN: 0
                out[3 * (y * out_width + x) + c] = static_cast<std::uint8_t>(clamped);
            }
}

}  // namespace softbody::render
