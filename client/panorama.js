// @ts-check
// The 360° view: the newest equirect painting, looked at from inside, drawn with WebGL2 at the display's rate.
//
// One full-screen triangle; each pixel turns its screen position into a direction and looks the direction
// up in the panorama (shared/MISSION.md "Other projections": longitude phi = (2s - 1) pi, 0 straight ahead
// and positive to the right; latitude theta = (1 - 2t) pi / 2, positive up). A per-pixel lookup has no mesh,
// so no seam and no pinched poles; the longitude wraps through the texture's REPEAT.
//
// Directions are given in the panorama's own frame: x along its camera's right r, y along its up u, z along
// its forward f (the camera the server painted it from). A view hands `draw` a 4x4 matrix `panoFromClip`
// that takes a clip-space point (x, y, 0, 1) of the view to a point along that pixel's ray in this frame.
// A stereo top-bottom painting (left eye on top) is sampled in one eye's half.

const VERTEX = `#version 300 es
in vec2 corner;
out vec2 clip;
void main() {
  clip = corner;
  gl_Position = vec4(corner, 0.0, 1.0);
}`;

const FRAGMENT = `#version 300 es
precision highp float;
const float PI = 3.14159265358979;
in vec2 clip;
uniform mat4 panoFromClip;
uniform sampler2D panorama;
uniform vec2 eyeRows;   // the eye's rows in texture coordinates: first row, height (0, 1 for a mono painting)
uniform float texel;    // half a texel row: the eye's half is never sampled across its edge
out vec4 color;
void main() {
  vec4 p = panoFromClip * vec4(clip, 0.0, 1.0);
  vec3 d = normalize(p.xyz / p.w);
  float phi = atan(d.x, d.z);
  float theta = asin(clamp(d.y, -1.0, 1.0));
  float s = phi / (2.0 * PI) + 0.5;
  float t = clamp(0.5 - theta / PI, texel, 1.0 - texel);
  color = vec4(texture(panorama, vec2(s, eyeRows.x + t * eyeRows.y)).rgb, 1.0);
}`;

function compile(gl, type, source) {
  const shader = gl.createShader(type);
  gl.shaderSource(shader, source);
  gl.compileShader(shader);
  if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(shader));
  return shader;
}

// ---- small vector and matrix helpers (column-major 4x4, as WebGL takes them) ----

export const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];

/** The inverse of a column-major 4x4 matrix (cofactors; null when singular). */
export function invert(m) {
  const [a00, a01, a02, a03, a10, a11, a12, a13, a20, a21, a22, a23, a30, a31, a32, a33] = m;
  const b00 = a00 * a11 - a01 * a10;
  const b01 = a00 * a12 - a02 * a10;
  const b02 = a00 * a13 - a03 * a10;
  const b03 = a01 * a12 - a02 * a11;
  const b04 = a01 * a13 - a03 * a11;
  const b05 = a02 * a13 - a03 * a12;
  const b06 = a20 * a31 - a21 * a30;
  const b07 = a20 * a32 - a22 * a30;
  const b08 = a20 * a33 - a23 * a30;
  const b09 = a21 * a32 - a22 * a31;
  const b10 = a21 * a33 - a23 * a31;
  const b11 = a22 * a33 - a23 * a32;
  const det = b00 * b11 - b01 * b10 + b02 * b09 + b03 * b08 - b04 * b07 + b05 * b06;
  if (!det) return null;
  const k = 1 / det;
  return [
    (a11 * b11 - a12 * b10 + a13 * b09) * k,
    (a02 * b10 - a01 * b11 - a03 * b09) * k,
    (a31 * b05 - a32 * b04 + a33 * b03) * k,
    (a22 * b04 - a21 * b05 - a23 * b03) * k,
    (a12 * b08 - a10 * b11 - a13 * b07) * k,
    (a00 * b11 - a02 * b08 + a03 * b07) * k,
    (a32 * b02 - a30 * b05 - a33 * b01) * k,
    (a20 * b05 - a22 * b02 + a23 * b01) * k,
    (a10 * b10 - a11 * b08 + a13 * b06) * k,
    (a01 * b08 - a00 * b10 - a03 * b06) * k,
    (a30 * b04 - a31 * b02 + a33 * b00) * k,
    (a21 * b02 - a20 * b04 - a23 * b00) * k,
    (a11 * b07 - a10 * b09 - a12 * b06) * k,
    (a00 * b09 - a01 * b07 + a02 * b06) * k,
    (a31 * b01 - a30 * b03 - a32 * b00) * k,
    (a20 * b03 - a21 * b01 + a22 * b00) * k,
  ];
}

/** The product a * b of two column-major 4x4 matrices. */
export function multiply(a, b) {
  const out = new Array(16).fill(0);
  for (let col = 0; col < 4; col++)
    for (let row = 0; row < 4; row++)
      for (let k = 0; k < 4; k++) out[col * 4 + row] += a[k * 4 + row] * b[col * 4 + k];
  return out;
}

/**
 * `panoFromClip` of a flat view: a pinhole with vertical field of view `fov` (degrees) and `aspect`
 * (width / height), looking along `forward` with `right` and `up`, unit vectors in the panorama's frame.
 */
export function flatView(forward, right, up, fov, aspect) {
  const h = Math.tan((fov * Math.PI) / 360);
  const x = right.map((v) => v * h * aspect);
  const y = up.map((v) => v * h);
  return [...x, 0, ...y, 0, 0, 0, 0, 0, ...forward, 1];
}

export class PanoramaView {
  /** @param {HTMLCanvasElement} canvas  a canvas of its own (WebGL2); throws when the browser has no WebGL2 */
  constructor(canvas) {
    this.canvas = canvas;
    // xrCompatible: the same context draws into a headset's layer (vr.js)
    const options = { alpha: false, antialias: false, xrCompatible: true };
    const gl = /** @type {WebGL2RenderingContext | null} */ (canvas.getContext("webgl2", options));
    if (!gl) throw new Error("this browser has no WebGL2");
    this.gl = gl;
    const program = gl.createProgram();
    gl.attachShader(program, compile(gl, gl.VERTEX_SHADER, VERTEX));
    gl.attachShader(program, compile(gl, gl.FRAGMENT_SHADER, FRAGMENT));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(program));
    this.program = program;
    this.uniforms = Object.fromEntries(
      ["panoFromClip", "panorama", "eyeRows", "texel"].map((name) => [name, gl.getUniformLocation(program, name)]),
    );
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    gl.bindBuffer(gl.ARRAY_BUFFER, gl.createBuffer());
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 3, -1, -1, 3]), gl.STATIC_DRAW); // covers the screen
    const corner = gl.getAttribLocation(program, "corner");
    gl.enableVertexAttribArray(corner);
    gl.vertexAttribPointer(corner, 2, gl.FLOAT, false, 0, 0);
    this.texture = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.REPEAT); // longitude wraps: no seam
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR); // no mipmaps: no seam from derivatives
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    this.layout = null; // {stereo, width, height} of the panorama held, null before the first
    this.drawn = 0; // frames drawn since the page opened (the tests and the overlay read it)
    this.uploaded = 0; // panoramas received and uploaded
  }

  /** Hold `bitmap` (an ImageBitmap of an equirect painting laid out as `stereo`) as the panorama to draw. */
  show(bitmap, stereo) {
    const gl = this.gl;
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, gl.RGBA, gl.UNSIGNED_BYTE, bitmap); // row 0 is the top: t = 0
    this.layout = { stereo, width: bitmap.width, height: bitmap.height };
    this.uploaded += 1;
  }

  /** Size the drawing buffer to `detail` x the canvas's size on screen in device pixels; true when it changed. */
  fit(detail = 1) {
    const scale = Math.min(devicePixelRatio || 1, 2) * detail;
    const width = Math.max(1, Math.round(this.canvas.clientWidth * scale));
    const height = Math.max(1, Math.round(this.canvas.clientHeight * scale));
    if (width === this.canvas.width && height === this.canvas.height) return false;
    [this.canvas.width, this.canvas.height] = [width, height];
    return true;
  }

  /**
   * Draw the panorama into the bound framebuffer's `viewport` ([x, y, width, height]) as seen through
   * `panoFromClip`; `eye` "left" or "right" samples that eye's half of a top-bottom painting.
   * @param {Float32Array | number[]} panoFromClip
   * @param {[number, number, number, number]} viewport
   * @param {"left" | "right"} [eye]
   */
  draw(panoFromClip, viewport, eye = "left") {
    const gl = this.gl;
    gl.viewport(...viewport);
    if (!this.layout) {
      gl.clearColor(0.07, 0.07, 0.08, 1);
      gl.clear(gl.COLOR_BUFFER_BIT);
      return;
    }
    const stereo = this.layout.stereo === "top-bottom";
    /** @type {[number, number]} */
    const rows = stereo ? [eye === "right" ? 0.5 : 0, 0.5] : [0, 1];
    gl.useProgram(this.program);
    gl.bindVertexArray(this.vao);
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D, this.texture);
    gl.uniform1i(this.uniforms.panorama, 0);
    gl.uniformMatrix4fv(this.uniforms.panoFromClip, false, panoFromClip);
    gl.uniform2f(this.uniforms.eyeRows, ...rows);
    gl.uniform1f(this.uniforms.texel, 0.5 / (this.layout.height * rows[1]));
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    this.drawn += 1;
  }

  /** Draw a flat view into the whole canvas (see `flatView`). */
  drawFlat(forward, right, up, fov) {
    this.gl.bindFramebuffer(this.gl.FRAMEBUFFER, null);
    const { width, height } = this.canvas;
    this.draw(flatView(forward, right, up, fov, width / height), [0, 0, width, height]);
  }

}
