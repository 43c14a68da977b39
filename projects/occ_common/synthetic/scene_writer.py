"""Writes the sensor data, labels and table records of one scene.

:class:`SceneWriter` is driven sweep by sweep by
:func:`.generate.generate_synthetic_nuscenes`: every LiDAR sweep becomes a
``.pcd.bin`` file with its ``sample_data`` and ``ego_pose`` records; every
key frame additionally gets a ``sample``, lidarseg labels, the rig's
camera images, ``sample_annotation`` records and both occupancy ground truths.
"""
import os
import os.path as osp
from typing import Dict, List

import cv2
import numpy as np

from .camera import Camera, finish_image, render_camera
from .geometry import invert_transform, yaw_quaternion
from .lidar import Sweep, scan_lidar
from .occupancy import (OCC3D_GRID, RAW_FREE, SURROUNDOCC_GRID, camera_mask,
                        lidar_mask, to_occ3d_semantics, to_surroundocc,
                        voxelize)
from .tables import NuScenesTables, make_token, visibility_token
from .world import World

#: Objects farther than this from the ego (m) get no sample_annotation.
ANNOTATION_RANGE = 60.0


def camera_label_path(image_filename: str) -> str:
    """Where the per-pixel class map of a camera image is written.

    Args:
        image_filename (str): The image's ``sample_data`` filename, e.g.
            ``samples/CAM_FRONT/<log>__CAM_FRONT__<ts>.jpg``.

    Returns:
        str: Path relative to the dataset root of a single-channel uint8
        PNG holding the raw lidarseg class seen at every pixel (0 = sky),
        e.g. ``synthetic_gt/cam_labels/CAM_FRONT/<log>__CAM_FRONT__<ts>.png``.
    """
    channel = osp.basename(osp.dirname(image_filename))
    stem = osp.splitext(osp.basename(image_filename))[0]
    return osp.join('synthetic_gt', 'cam_labels', channel, f'{stem}.png')


class SceneWriter:
    """Writes one scene; see the module docstring.

    Args:
        out_dir (str): Dataset root.
        version (str): Table / lidarseg folder name.
        seed (int): Generator seed (tokens, sensor noise).
        scene_index (int): Index of the scene.
        scene_name (str): ``scene-XXXX``.
        world (World): The scene's world.
        cameras (List[Camera]): The camera rig.
        lidar2ego (np.ndarray): LIDAR_TOP -> ego. Shape (4, 4).
        tables (NuScenesTables): Where records go.
        logfile (str): Log name, the prefix of every file name.
        base_us (int): Timestamp of the first sweep, microseconds.
        azimuth_bins (int): LiDAR azimuth steps per revolution.
        camera_mask_rays (tuple): ``(width, height)`` of the ray grid per
            camera for ``mask_camera``.
        write_camera_labels (bool): Write per-pixel class maps.
        lidar_ring (bool): Store the ring index as a fifth value per
            LiDAR point. Defaults to True.
    """

    def __init__(self, out_dir: str, version: str, seed: int,
                 scene_index: int, scene_name: str, world: World,
                 cameras: List[Camera], lidar2ego: np.ndarray,
                 tables: NuScenesTables, logfile: str, base_us: int,
                 azimuth_bins: int, camera_mask_rays: tuple,
                 write_camera_labels: bool, lidar_ring: bool = True):
        self.out_dir, self.version, self.seed = out_dir, version, seed
        self.index, self.name, self.world = scene_index, scene_name, world
        self.cameras, self.lidar2ego = cameras, lidar2ego
        self.tables, self.logfile, self.base_us = tables, logfile, base_us
        self.azimuth_bins = azimuth_bins
        self.write_camera_labels = write_camera_labels
        self.lidar_ring = lidar_ring
        self.mask_cameras = [cam.scaled(*camera_mask_rays) for cam in cameras]
        self.rng = np.random.default_rng([seed, scene_index, 1])
        self.scene_token = make_token(seed, 'scene', scene_index)
        self.sample_tokens: List[str] = []
        self.counts = dict(num_samples=0, num_sweeps=0, num_images=0,
                           num_lidar_points=0, num_annotations=0)
        self.paths: Dict[str, List[str]] = dict(surroundocc=[], occ3d=[],
                                                lidarseg=[])
        self.annotations: Dict[int, List[dict]] = {}
        self.calib = {}
        for camera in cameras:
            self.calib[camera.name] = self._calibrate(
                camera.name, camera.cam2ego, camera.intrinsic)
        self.calib['LIDAR_TOP'] = self._calibrate('LIDAR_TOP', lidar2ego)
        self._lidar = None

    def _token(self, *parts) -> str:
        return make_token(self.seed, *parts)

    def _calibrate(self, channel, sensor2ego, intrinsic=None) -> str:
        token = self._token('calibrated_sensor', self.index, channel)
        self.tables.add_calibrated_sensor(
            token, self._token('sensor', channel), sensor2ego, intrinsic)
        return token

    def _sample_token(self, sample: int) -> str:
        return self._token('sample', self.index, sample)

    def _sd_token(self, channel: str, position: int) -> str:
        return self._token('sample_data', self.index, channel, position)

    def _timestamp(self, t: float) -> int:
        return self.base_us + int(round(t * 1e6))

    def _path(self, *parts) -> str:
        path = osp.join(self.out_dir, *parts)
        os.makedirs(osp.dirname(path), exist_ok=True)
        return path

    def _add_sample_data(self, channel, position, sample, count, t, ego_pose,
                         filename, key, **extra) -> str:
        token = self._sd_token(channel, position)
        ego_token = self._token('ego_pose', self.index, channel, position)
        self.tables.add_ego_pose(ego_token, self._timestamp(t), ego_pose)
        self.tables.add(
            'sample_data', token=token,
            sample_token=self._sample_token(sample),
            ego_pose_token=ego_token,
            calibrated_sensor_token=self.calib[channel],
            timestamp=self._timestamp(t), filename=filename,
            is_key_frame=key,
            prev=self._sd_token(channel, position - 1) if position else '',
            next=(self._sd_token(channel, position + 1)
                  if position + 1 < count else ''),
            **extra)
        return token

    def write_sweep(self, position: int, t: float, sample: int, key: bool,
                    count: int) -> Sweep:
        """Captures and writes LiDAR sweep number ``position``.

        Args:
            position (int): Sweep index within the scene.
            t (float): Seconds since the scene's first sweep.
            sample (int): Index of the sample the sweep belongs to (the
                nearest key frame's).
            key (bool): Whether the sweep is a key frame.
            count (int): Sweeps in the scene.

        Returns:
            Sweep: The sweep.
        """
        ego_pose = self.world.ego_pose(t)
        sweep = scan_lidar(self.world, ego_pose @ self.lidar2ego, t,
                           self.azimuth_bins, self.rng,
                           with_ring=self.lidar_ring)
        folder = 'samples' if key else 'sweeps'
        filename = (f'{folder}/LIDAR_TOP/{self.logfile}__LIDAR_TOP__'
                    f'{self._timestamp(t)}.pcd.bin')
        sweep.points.tofile(self._path(filename))
        token = self._add_sample_data('LIDAR_TOP', position, sample, count,
                                      t, ego_pose, filename, key,
                                      fileformat='pcd', height=0, width=0)
        self.counts['num_sweeps'] += 1
        self._lidar = (token, filename)
        return sweep

    def write_key_frame(self, sample: int, num_samples: int, t: float,
                        sweeps: List[Sweep]) -> None:
        """Writes the key frame whose LiDAR sweep was written last.

        Args:
            sample (int): Sample index within the scene.
            num_samples (int): Samples in the scene.
            t (float): Seconds since the scene's first sweep.
            sweeps (List[Sweep]): The key frame's sweep last, preceded by
                the sweeps aggregated into ``mask_lidar``.
        """
        sweep, (lidar_token, lidar_file) = sweeps[-1], self._lidar
        token = self._sample_token(sample)
        self.tables.add(
            'sample', token=token, timestamp=self._timestamp(t),
            scene_token=self.scene_token,
            prev=self._sample_token(sample - 1) if sample else '',
            next=(self._sample_token(sample + 1)
                  if sample + 1 < num_samples else ''))
        self.sample_tokens.append(token)
        self.counts['num_samples'] += 1
        self.counts['num_lidar_points'] += len(sweep.points)
        seg_file = f'lidarseg/{self.version}/{lidar_token}_lidarseg.bin'
        sweep.raw_class.astype(np.uint8).tofile(self._path(seg_file))
        self.tables.add('lidarseg', token=lidar_token,
                        sample_data_token=lidar_token, filename=seg_file)
        self.paths['lidarseg'].append(osp.join(self.out_dir, seg_file))
        ego_pose = self.world.ego_pose(t)
        visible = np.zeros(len(self.world.boxes))
        projected = np.zeros(len(self.world.boxes))
        for cam_index, camera in enumerate(self.cameras):
            rendered = render_camera(self.world, camera, ego_pose, t)
            rng = np.random.default_rng(
                [self.seed, self.index, 2, sample, cam_index])
            image = finish_image(rendered['radiance'], self.world, rng)
            filename = (f'samples/{camera.name}/{self.logfile}__'
                        f'{camera.name}__{self._timestamp(t)}.jpg')
            cv2.imwrite(self._path(filename), image[..., ::-1],
                        [cv2.IMWRITE_JPEG_QUALITY, 92])
            if self.write_camera_labels:
                cv2.imwrite(self._path(camera_label_path(filename)),
                            rendered['raw_class'])
            self._add_sample_data(camera.name, sample, sample, num_samples,
                                  t, ego_pose, filename, True,
                                  fileformat='jpg', height=camera.height,
                                  width=camera.width)
            visible += rendered['box_visible']
            projected += rendered['box_projected']
            self.counts['num_images'] += 1
        self._annotate(token, sample, t, ego_pose, sweep, visible, projected)
        self._write_occupancy(token, t, ego_pose, lidar_file, sweeps)

    def _annotate(self, sample_token, sample, t, ego_pose, sweep, visible,
                  projected) -> None:
        boxes = self.world.boxes
        centers = boxes.centers_at(t)
        near = np.hypot(*(centers[:, :2] - ego_pose[:2, 3]).T)
        lidar_pts = np.bincount(sweep.target[sweep.target >= 0],
                                minlength=len(boxes))
        for box in np.nonzero(boxes.annotated
                              & (near <= ANNOTATION_RANGE))[0]:
            fraction = visible[box] / projected[box] if projected[box] else 0
            attribute = boxes.attribute[box]
            length, width, height = boxes.size[box]
            record = self.tables.add(
                'sample_annotation',
                token=self._token('sample_annotation', self.index, box,
                                  sample),
                sample_token=sample_token,
                instance_token=self._token('instance', self.index, box),
                visibility_token=visibility_token(fraction),
                attribute_tokens=([self.tables.attribute_token(attribute)]
                                  if attribute else []),
                translation=[float(v) for v in centers[box]],
                size=[float(width), float(length), float(height)],
                rotation=[float(v) for v in yaw_quaternion(boxes.yaw[box])],
                prev='', next='', num_lidar_pts=int(lidar_pts[box]),
                num_radar_pts=0)
            self.annotations.setdefault(int(box), []).append(record)
            self.counts['num_annotations'] += 1

    def _write_occupancy(self, sample_token, t, ego_pose, lidar_file,
                         sweeps) -> None:
        raw = voxelize(self.world, t, ego_pose, OCC3D_GRID)
        mask_lidar = lidar_mask(OCC3D_GRID, invert_transform(ego_pose),
                                sweeps)
        mask_camera = camera_mask(OCC3D_GRID, raw != RAW_FREE,
                                  self.mask_cameras,
                                  [cam.cam2ego for cam in self.mask_cameras])
        path = self._path('gts', self.name, sample_token, 'labels.npz')
        np.savez_compressed(path, semantics=to_occ3d_semantics(raw),
                            mask_lidar=mask_lidar.astype(np.uint8),
                            mask_camera=mask_camera.astype(np.uint8))
        self.paths['occ3d'].append(path)
        raw = voxelize(self.world, t, ego_pose @ self.lidar2ego,
                       SURROUNDOCC_GRID)
        path = self._path('nuscenes_occ', 'samples',
                          f'{osp.basename(lidar_file)}.npy')
        np.save(path, to_surroundocc(raw))
        self.paths['surroundocc'].append(path)

    def finish(self, description: str, log_token: str) -> None:
        """Links annotations into instances and writes the scene record.

        Args:
            description (str): The scene's description.
            log_token (str): Token of the scene's log.
        """
        for box, records in sorted(self.annotations.items()):
            for before, after in zip(records[:-1], records[1:]):
                before['next'], after['prev'] = after['token'], before[
                    'token']
            self.tables.add(
                'instance', token=records[0]['instance_token'],
                category_token=self.tables.category_token(
                    int(self.world.boxes.raw_class[box])),
                nbr_annotations=len(records),
                first_annotation_token=records[0]['token'],
                last_annotation_token=records[-1]['token'])
        self.tables.add('scene', token=self.scene_token, log_token=log_token,
                        nbr_samples=len(self.sample_tokens),
                        first_sample_token=self.sample_tokens[0],
                        last_sample_token=self.sample_tokens[-1],
                        name=self.name, description=description)
