// @ts-check
// Walk frames scaled up to the canvas with their edges kept sharp: an edge-aware upscale in WebGL2, after AMD
// FidelityFX Super Resolution 1's EASU (ffx_fsr1.h, FsrEasuF; MIT licence), ported to GLSL.
//
// While walking, the server paints frames smaller than the canvas (a quarter of its width, or half). Scaled up
// with plain bilinear smoothing, every painted pixel shows as a soft block and every edge as a staircase. EASU
// reads the 12 frame pixels around each canvas pixel, finds the local edge's direction and strength from the
// luma differences of the 4 nearest, and weighs the 12 with a Lanczos-like kernel turned along that edge:
// stretched along it (the edge stays continuous, no staircase), narrowed across it (the edge stays sharp).
// The result is clamped to the range of the 4 nearest pixels, so the kernel's negative lobes add no ringing.
// One departure from EASU: where there is no edge the result leans to bilinear, in proportion to EASU's own
// edge strength. A walk frame is a JPEG (quality 70): sharpening its flat areas only raises its noise (measured
// against the full painting: PSNR up 0.07 to 0.1 dB over plain EASU, edges as sharp within 3%).
//
// The canvas stays a 2D canvas (everything else draws and reads it as one): the upscale renders into a WebGL2
// canvas of its own, drawn onto it. Without WebGL2 (or once its context is lost) frames are drawn smoothed as
// before. The choice is the panel's "walk quality", kept in this browser:
//   auto    EASU for a frame smaller than the canvas where a GPU draws it; smoothing where WebGL runs on the
//           CPU (SwiftShader: 0.4 to 0.7 s a 1280x720 frame on a busy 2-core machine, against 20 to 75 ms
//           smoothed, which would cap the walk near 2 frames a second)
//   sharp   EASU whenever the frame's size is not the canvas's, on a GPU or not
//   smooth  the 2D canvas's own smoothing (bilinear)

export const WALK_QUALITIES = ["auto", "sharp", "smooth"];
const STORE = "rcp.walkQuality";

const VERTEX = `#version 300 es
void main() {  // one triangle over the whole viewport
  vec2 corner = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(corner * 2.0 - 1.0, 0.0, 1.0);
}`;

const EASU = `#version 300 es
precision highp float;
precision highp int;
uniform sampler2D frame;
uniform vec2 scale;   // frame size / output size
uniform float outHeight;
uniform ivec2 last;   // the frame's last column and row
out vec4 color;

// the frame's pixel (column, row from the top), clamped to its edge
vec3 at(ivec2 p) { return texelFetch(frame, clamp(p, ivec2(0), last), 0).rgb; }
// FSR's cheapest luma (times 2): enough to find edges
float luma(vec3 c) { return c.b * 0.5 + (c.r * 0.5 + c.g); }

// One of the 4 nearest pixels (c, with a above, b left, d right, e below) adds its gradient, and how much its
// two sides agree (an edge, not a lone pixel), weighted bilinearly (w). FsrEasuSetF.
void edge(inout vec2 dir, inout float len, float w, float a, float b, float c, float d, float e) {
  float dirX = d - b, dirY = e - a;
  float lenX = clamp(abs(dirX) / max(max(abs(d - c), abs(c - b)), 1e-6), 0.0, 1.0);
  float lenY = clamp(abs(dirY) / max(max(abs(e - c), abs(c - a)), 1e-6), 0.0, 1.0);
  dir += vec2(dirX, dirY) * w;
  len += (lenX * lenX + lenY * lenY) * w;
}

// One tap at offset 'off' (frame pixels) of the kernel turned to 'dir' and scaled by 'len2': a polynomial
// Lanczos-2 approximation whose window 'lob' widens with the edge's strength, cut at 'clp'. FsrEasuTapF.
void tap(inout vec3 sum, inout float total, vec2 off, vec2 dir, vec2 len2, float lob, float clp, vec3 c) {
  vec2 v = vec2(dot(off, dir), dot(off, vec2(-dir.y, dir.x))) * len2;
  float d2 = min(dot(v, v), clp);
  float wB = 0.4 * d2 - 1.0;
  float wA = lob * d2 - 1.0;
  wB *= wB;
  wA *= wA;
  float w = (1.5625 * wB - 0.5625) * wA;
  sum += c * w;
  total += w;
}

void main() {
  // this output pixel's centre in frame pixels, from the top; f is the nearest pixel up and left of it
  vec2 pp = vec2(gl_FragCoord.x, outHeight - gl_FragCoord.y) * scale - 0.5;
  vec2 fp = floor(pp);
  pp -= fp;
  ivec2 o = ivec2(fp);
  //    b c
  //  e f g h
  //  i j k l
  //    n o
  vec3 b = at(o + ivec2(0, -1)), c = at(o + ivec2(1, -1));
  vec3 e = at(o + ivec2(-1, 0)), f = at(o), g = at(o + ivec2(1, 0)), h = at(o + ivec2(2, 0));
  vec3 i = at(o + ivec2(-1, 1)), j = at(o + ivec2(0, 1)), k = at(o + ivec2(1, 1)), l = at(o + ivec2(2, 1));
  vec3 n = at(o + ivec2(0, 2)), q = at(o + ivec2(1, 2));
  float bL = luma(b), cL = luma(c), eL = luma(e), fL = luma(f), gL = luma(g), hL = luma(h);
  float iL = luma(i), jL = luma(j), kL = luma(k), lL = luma(l), nL = luma(n), qL = luma(q);

  // ---- the edge: its direction and strength, bilinear over the 4 nearest ----
  vec2 dir = vec2(0.0);
  float len = 0.0;
  edge(dir, len, (1.0 - pp.x) * (1.0 - pp.y), bL, eL, fL, gL, jL);
  edge(dir, len, pp.x * (1.0 - pp.y), cL, fL, gL, hL, kL);
  edge(dir, len, (1.0 - pp.x) * pp.y, fL, iL, jL, kL, nL);
  edge(dir, len, pp.x * pp.y, gL, jL, kL, lL, qL);
  float dir2 = dot(dir, dir);
  dir = dir2 < 1.0 / 32768.0 ? vec2(1.0, 0.0) : dir * inversesqrt(dir2);
  len = 0.5 * len;
  len *= len;

  // ---- the kernel: stretched along the edge (1 to sqrt 2 on diagonals), narrowed across it ----
  float stretch = 1.0 / max(abs(dir.x), abs(dir.y));
  vec2 len2 = vec2(1.0 + (stretch - 1.0) * len, 1.0 - 0.5 * len);
  float lob = 0.5 + ((1.0 / 4.0 - 0.04) - 0.5) * len;
  float clp = 1.0 / lob;

  vec3 sum = vec3(0.0);
  float total = 0.0;
  tap(sum, total, vec2(0.0, -1.0) - pp, dir, len2, lob, clp, b);
  tap(sum, total, vec2(1.0, -1.0) - pp, dir, len2, lob, clp, c);
  tap(sum, total, vec2(-1.0, 1.0) - pp, dir, len2, lob, clp, i);
  tap(sum, total, vec2(0.0, 1.0) - pp, dir, len2, lob, clp, j);
  tap(sum, total, vec2(0.0, 0.0) - pp, dir, len2, lob, clp, f);
  tap(sum, total, vec2(-1.0, 0.0) - pp, dir, len2, lob, clp, e);
  tap(sum, total, vec2(1.0, 1.0) - pp, dir, len2, lob, clp, k);
  tap(sum, total, vec2(2.0, 1.0) - pp, dir, len2, lob, clp, l);
  tap(sum, total, vec2(2.0, 0.0) - pp, dir, len2, lob, clp, h);
  tap(sum, total, vec2(1.0, 0.0) - pp, dir, len2, lob, clp, g);
  tap(sum, total, vec2(1.0, 2.0) - pp, dir, len2, lob, clp, q);
  tap(sum, total, vec2(0.0, 2.0) - pp, dir, len2, lob, clp, n);

  // ---- deringing: within the range of the 4 nearest ----
  vec3 lo = min(min(f, g), min(j, k)), hi = max(max(f, g), max(j, k));
  vec3 sharp = clamp(sum / total, lo, hi);

  // ---- away from edges, bilinear: the kernel's sharpening would only raise the JPEG's noise there ----
  vec3 soft = mix(mix(f, g, pp.x), mix(j, k, pp.x), pp.y);
  color = vec4(mix(soft, sharp, len), 1.0);
}`;

/** The walk quality this browser chose last ("auto" at first). */
export function storedQuality() {
  const stored = localStorage.getItem(STORE);
  return WALK_QUALITIES.includes(stored) ? stored : "auto";
}

/** The panel's walk-quality select: shows the stored choice, stores each new one and tells `changed(quality)`. */
export function qualityControl(select, changed) {
  select.value = storedQuality();
  select.addEventListener("change", () => {
    const quality = WALK_QUALITIES.includes(select.value) ? select.value : "auto";
    localStorage.setItem(STORE, quality);
    changed(quality);
  });
}

export class Upscaler {
  constructor() {
    this.quality = storedQuality();
    this.canvas = document.createElement("canvas");
    this.problem = null; // why the upscale cannot run here (then frames are drawn smoothed)
    this.draws = 0; // frames drawn with EASU (the tests watch it)
    this.accelerated = false; // WebGL2 on a GPU, not on the CPU: "auto" upscales only then
    const gl = this.canvas.getContext("webgl2", { alpha: false, antialias: false, depth: false, stencil: false });
    if (!gl) {
      this.problem = "no WebGL2";
      return;
    }
    this.gl = gl;
    this.accelerated = onGpu();
    this.canvas.addEventListener("webglcontextlost", () => (this.problem = "the WebGL context was lost"));
    try {
      this.program = program(gl, VERTEX, EASU);
    } catch (error) {
      this.problem = error.message;
      return;
    }
    this.uniforms = Object.fromEntries(
      ["frame", "scale", "outHeight", "last"].map((name) => [name, gl.getUniformLocation(this.program, name)]),
    );
    this.texture = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    for (const [name, value] of [
      [gl.TEXTURE_MIN_FILTER, gl.NEAREST],
      [gl.TEXTURE_MAG_FILTER, gl.NEAREST],
      [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE],
      [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE],
    ])
      gl.texParameteri(gl.TEXTURE_2D, name, value);
  }

  /** Whether a frame of `frameWidth x frameHeight` goes through EASU onto a canvas of `width x height`. */
  wanted(frameWidth, frameHeight, width, height) {
    if (this.problem || this.quality === "smooth") return false;
    if (frameWidth === width && frameHeight === height) return false; // nothing to scale
    return this.quality === "sharp" || (this.accelerated && frameWidth <= width && frameHeight <= height);
  }

  /** Draws `bitmap` scaled to `width x height` onto the 2D `context` with EASU; false if it could not. */
  draw(bitmap, context, width, height) {
    const gl = this.gl;
    if (this.problem || gl.isContextLost()) return false;
    if (this.canvas.width !== width || this.canvas.height !== height) [this.canvas.width, this.canvas.height] = [width, height];
    gl.viewport(0, 0, width, height);
    gl.useProgram(this.program);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false); // row 0 is the frame's top: the shader counts rows down
    gl.pixelStorei(gl.UNPACK_PREMULTIPLY_ALPHA_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_COLORSPACE_CONVERSION_WEBGL, gl.NONE); // the JPEG's values, as the 2D path draws them
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, gl.RGBA, gl.UNSIGNED_BYTE, bitmap);
    gl.uniform1i(this.uniforms.frame, 0);
    gl.uniform2f(this.uniforms.scale, bitmap.width / width, bitmap.height / height);
    gl.uniform1f(this.uniforms.outHeight, height);
    gl.uniform2i(this.uniforms.last, bitmap.width - 1, bitmap.height - 1);
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    context.drawImage(this.canvas, 0, 0, width, height); // in the same task: the drawing buffer is still there
    this.draws += 1;
    return true;
  }
}

/** Whether WebGL2 runs on a GPU: a browser refuses a context "with a major performance caveat" (software). */
function onGpu() {
  const probe = document.createElement("canvas").getContext("webgl2", { failIfMajorPerformanceCaveat: true });
  if (!probe) return false;
  const info = probe.getExtension("WEBGL_debug_renderer_info");
  const renderer = info ? String(probe.getParameter(info.UNMASKED_RENDERER_WEBGL)) : "";
  probe.getExtension("WEBGL_lose_context")?.loseContext(); // one context fewer held
  return !/swiftshader|llvmpipe|softpipe|software/i.test(renderer);
}

function program(gl, vertexSource, fragmentSource) {
  const made = gl.createProgram();
  for (const [type, source] of [
    [gl.VERTEX_SHADER, vertexSource],
    [gl.FRAGMENT_SHADER, fragmentSource],
  ]) {
    const shader = gl.createShader(type);
    gl.shaderSource(shader, source);
    gl.compileShader(shader);
    if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error(`upscale shader: ${gl.getShaderInfoLog(shader)}`);
    gl.attachShader(made, shader);
  }
  gl.linkProgram(made);
  if (!gl.getProgramParameter(made, gl.LINK_STATUS)) throw new Error(`upscale program: ${gl.getProgramInfoLog(made)}`);
  return made;
}
