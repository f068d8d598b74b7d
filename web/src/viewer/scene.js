// The WebGL scene of the viewer: a shape (and optionally a second one overlaid), orbit,
// zoom and pan with the mouse or the keyboard, and the distance colour map between them.

import {
  BufferAttribute,
  Color,
  DirectionalLight,
  HemisphereLight,
  Mesh,
  MeshBasicMaterial,
  MeshStandardMaterial,
  PerspectiveCamera,
  Scene,
  SphereGeometry,
  Sphere,
  Vector3,
  WebGLRenderer,
} from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
import { colourAt, nearestDistances } from "./distance.js";

/** Background colour of the canvas (the browser test tells the shape from it). */
export const BACKGROUND = "#f3f5f8";

const SHAPE_COLOUR = 0xcd5c50;
const OVERLAY_COLOUR = 0x4a6fa5;

/** The first triangle mesh of a parsed glTF document. */
async function parseGlb(bytes) {
  const gltf = await new GLTFLoader().parseAsync(bytes, "");
  let found = null;
  gltf.scene.traverse((node) => {
    if (!found && node.isMesh) found = node;
  });
  if (!found) throw new Error("the GLB holds no mesh");
  found.updateWorldMatrix(true, false);
  const geometry = found.geometry.clone().applyMatrix4(found.matrixWorld);
  if (!geometry.getAttribute("normal")) geometry.computeVertexNormals();
  return geometry;
}

export class ShapeScene {
  constructor(canvas) {
    this.canvas = canvas;
    this.renderer = new WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.renderer.setClearColor(new Color(BACKGROUND));
    this.scene = new Scene();
    this.camera = new PerspectiveCamera(35, 1, 0.1, 1e5);
    this.camera.up.set(0, 0, 1);
    this.scene.add(new HemisphereLight(0xffffff, 0x667080, 1.4));
    this.light = new DirectionalLight(0xffffff, 1.6);
    this.camera.add(this.light);
    this.light.position.set(-0.4, 0.6, 1);
    this.scene.add(this.camera);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.listenToKeyEvents(canvas);
    this.controls.addEventListener("change", () => this.render());
    this.shape = null;
    this.overlay = null;
    this.markers = [];
    this.wireframe = false;
    this.resize = new ResizeObserver(() => this.fit());
    this.resize.observe(canvas.parentElement);
  }

  /** Shows the GLB `bytes` as the main shape (replacing any). */
  async setShape(bytes) {
    const geometry = await parseGlb(bytes);
    this.remove("shape");
    const material = new MeshStandardMaterial({ color: SHAPE_COLOUR, roughness: 0.55, metalness: 0.05 });
    this.shape = new Mesh(geometry, material);
    this.scene.add(this.shape);
    this.frame();
  }

  /** Overlays the GLB `bytes` and colours the main shape by distance to it; null removes it. */
  async setOverlay(bytes) {
    this.remove("overlay");
    const material = this.shape.material;
    material.vertexColors = false;
    material.color.set(SHAPE_COLOUR);
    material.needsUpdate = true;
    if (!bytes) {
      this.render();
      return null;
    }
    const geometry = await parseGlb(bytes);
    const overlayMaterial = new MeshStandardMaterial({
      color: OVERLAY_COLOUR, transparent: true, opacity: 0.35, depthWrite: false, wireframe: this.wireframe,
    });
    this.overlay = new Mesh(geometry, overlayMaterial);
    this.scene.add(this.overlay);
    const distances = nearestDistances(this.shape.geometry.getAttribute("position").array, geometry.getAttribute("position").array);
    const max = distances.reduce((m, d) => Math.max(m, d), 0) || 1;
    const colours = new Float32Array(distances.length * 3);
    distances.forEach((d, i) => colours.set(colourAt(d / max), 3 * i));
    this.shape.geometry.setAttribute("color", new BufferAttribute(colours, 3));
    material.vertexColors = true;
    material.color.set(0xffffff);
    material.needsUpdate = true;
    this.render();
    const mean = distances.reduce((s, d) => s + d, 0) / distances.length;
    return { max, mean };
  }

  /**
   * Small spheres at labelled points (e.g. openings), in mm. They are drawn over the surface:
   * an opening's cap lies where the simulation mesh trims the vessel, inside the closed shape.
   */
  setMarkers(points) {
    for (const m of this.markers) {
      this.scene.remove(m);
      m.geometry.dispose();
      m.material.dispose();
    }
    const radius = this.radius() * 0.04;
    this.markers = points.map(([x, y, z]) => {
      const m = new Mesh(new SphereGeometry(radius, 16, 12), new MeshBasicMaterial({ color: 0x1f7a4a, depthTest: false }));
      m.renderOrder = 10;
      m.position.set(x, y, z);
      this.scene.add(m);
      return m;
    });
    this.render();
  }

  remove(which) {
    const mesh = this[which];
    if (!mesh) return;
    this.scene.remove(mesh);
    mesh.geometry.dispose();
    mesh.material.dispose();
    this[which] = null;
  }

  radius() {
    if (!this.shape) return 1;
    this.shape.geometry.computeBoundingSphere();
    return this.shape.geometry.boundingSphere.radius;
  }

  /** Looks at the shape from a three-quarter view that shows all of it. */
  frame() {
    if (!this.shape) return;
    this.shape.geometry.computeBoundingSphere();
    const sphere = new Sphere().copy(this.shape.geometry.boundingSphere);
    const distance = sphere.radius / Math.sin((this.camera.fov * Math.PI) / 360) * 1.1;
    const direction = new Vector3(0.5, -0.866, 0.27).normalize();
    this.controls.target.copy(sphere.center);
    this.camera.position.copy(sphere.center).addScaledVector(direction, distance);
    this.camera.near = distance / 100;
    this.camera.far = distance * 100;
    this.camera.updateProjectionMatrix();
    this.controls.update();
    this.fit();
  }

  /** Turns the camera about the vertical axis through the target by `degrees`. */
  rotate(degrees) {
    const offset = this.camera.position.clone().sub(this.controls.target);
    offset.applyAxisAngle(new Vector3(0, 0, 1), (degrees * Math.PI) / 180);
    this.camera.position.copy(this.controls.target).add(offset);
    this.controls.update();
  }

  /** Moves the camera towards (factor < 1) or away from the target. */
  zoom(factor) {
    const offset = this.camera.position.clone().sub(this.controls.target).multiplyScalar(factor);
    this.camera.position.copy(this.controls.target).add(offset);
    this.controls.update();
  }

  toggleWireframe() {
    this.wireframe = !this.wireframe;
    for (const mesh of [this.shape, this.overlay]) {
      if (mesh) mesh.material.wireframe = this.wireframe;
    }
    this.render();
    return this.wireframe;
  }

  fit() {
    const box = this.canvas.parentElement.getBoundingClientRect();
    const width = Math.max(1, Math.floor(box.width));
    const height = Math.max(1, Math.floor(box.height));
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  render() {
    this.renderer.render(this.scene, this.camera);
  }

  dispose() {
    this.resize.disconnect();
    this.controls.dispose();
    this.remove("shape");
    this.remove("overlay");
    this.renderer.dispose();
  }
}
