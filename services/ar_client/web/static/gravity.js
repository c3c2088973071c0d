// The device's gravity, in the camera frame of the picture sent, for each frame.
//
// Every tablet has an accelerometer. With gravity known the server fixes the camera's roll and
// pitch, which tells a single tag's two planar poses apart (one of them tilts the camera wrongly).
//
// Sources, best first: the Generic Sensor API's GravitySensor (gravity alone, hand motion removed
// by the platform), else `devicemotion`'s accelerationIncludingGravity, low-passed so the hand's
// own accelerations average out. Both report the reaction to gravity (pointing up, about 9.8 m/s²
// when still) in device coordinates: x to the right of the screen, y up the screen, z out of the
// screen towards the user, in the device's natural orientation.
//
// The picture is in the *screen's* orientation, so the reading is first turned by the screen angle,
// then taken into OpenCV camera axes of the rear camera (x right, y down, z forward, i.e. out of the
// back of the device), pointing down: g_cam = (−a_x, a_y, a_z) of the screen-aligned reaction a.

const SMOOTHING = 0.2; // share of each devicemotion sample in the low-passed value
const STALE_MS = 1000; // a reading older than this is not sent

export class GravitySource {
  constructor() {
    this.value = null; // screen-aligned reaction [x, y, z], m/s²
    this.at = 0;
    this.kind = "none";
    this.onMotion = (e) => this.motion(e);
    window.addEventListener("devicemotion", this.onMotion);
    this.startSensor();
  }

  startSensor() {
    if (typeof window.GravitySensor !== "function") return;
    try {
      const sensor = new window.GravitySensor({ frequency: 30 });
      sensor.addEventListener("reading", () => this.take([sensor.x, sensor.y, sensor.z], "sensor", 1));
      sensor.addEventListener("error", () => {}); // no sensor or no permission: devicemotion remains
      sensor.start();
      this.sensor = sensor;
    } catch (err) {
      // Blocked by a permissions policy or unsupported: devicemotion remains.
    }
  }

  // iOS asks the user first; called from a tap (a permission prompt needs a user gesture).
  async ask() {
    const D = window.DeviceMotionEvent;
    if (D && typeof D.requestPermission === "function") {
      try { await D.requestPermission(); } catch (err) { /* refused: frames go without gravity */ }
    }
  }

  motion(event) {
    const a = event.accelerationIncludingGravity;
    if (!a || a.x === null || a.y === null || a.z === null) return;
    if (this.kind === "sensor" && performance.now() - this.at < STALE_MS) return; // the better source is live
    this.take([a.x, a.y, a.z], "devicemotion", SMOOTHING);
  }

  take(device, kind, share) {
    if (!device.every(Number.isFinite)) return;
    const s = screenAligned(device, screenAngle());
    const fresh = this.value !== null && this.kind === kind && performance.now() - this.at < STALE_MS;
    this.value = fresh ? this.value.map((v, i) => v + share * (s[i] - v)) : s;
    this.kind = kind;
    this.at = performance.now();
  }

  // Gravity in the camera frame (OpenCV axes, pointing down, m/s²), or null when unknown or stale.
  current() {
    if (this.value === null || performance.now() - this.at > STALE_MS) return null;
    const [x, y, z] = this.value;
    return [-x, y, z];
  }
}

function screenAngle() {
  const o = window.screen && window.screen.orientation;
  if (o && Number.isFinite(o.angle)) return o.angle;
  return Number.isFinite(window.orientation) ? window.orientation : 0;
}

// Device axes → screen axes when the device is turned `angle` degrees counter-clockwise from its
// natural orientation (screen.orientation.angle; the page then draws upright again): the device's
// axes are turned by +angle against the screen's, so a vector's screen coordinates are the device's
// turned by +angle. E.g. 90: the device's top points left, its y axis is the screen's −x.
export function screenAligned([x, y, z], angle) {
  const r = (angle * Math.PI) / 180;
  const c = Math.cos(r), s = Math.sin(r);
  return [c * x - s * y, s * x + c * y, z];
}
