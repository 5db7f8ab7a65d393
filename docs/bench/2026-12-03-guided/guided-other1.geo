scene other1, database guided-other1.db
distance: symmetric epipolar distance: the larger of the two point-to-epipolar-line distances, px

| pair | config | inliers | ≤ 1 px | ≤ 2 px | ≤ 4 px | median px | on surface | true ≤ 1 px | true ≤ 2 px | true ≤ 4 px |
|---|---|---|---|---|---|---|---|---|---|---|
| view0.png view1.png | 6 | 4899 | 93.6 % | 98.7 % | 100.0 % | 0.18 | 4899 | 88.8 % | 97.8 % | 99.9 % |
| view0.png view2.png | 6 | 4311 | 93.8 % | 98.9 % | 100.0 % | 0.17 | 4311 | 87.8 % | 97.6 % | 99.9 % |
| view0.png view3.png | 6 | 3824 | 92.9 % | 98.7 % | 100.0 % | 0.19 | 3824 | 86.1 % | 96.8 % | 99.8 % |
| view0.png view4.png | 6 | 3732 | 93.3 % | 98.8 % | 99.9 % | 0.19 | 3732 | 85.6 % | 97.0 % | 99.6 % |
| view1.png view2.png | 6 | 5106 | 95.1 % | 99.0 % | 100.0 % | 0.14 | 5106 | 89.6 % | 98.0 % | 100.0 % |
| view1.png view3.png | 6 | 4328 | 94.3 % | 98.9 % | 100.0 % | 0.17 | 4328 | 88.0 % | 97.8 % | 99.9 % |
| view1.png view4.png | 6 | 4257 | 93.6 % | 98.7 % | 100.0 % | 0.17 | 4257 | 86.8 % | 97.5 % | 99.9 % |
| view2.png view3.png | 6 | 4438 | 94.1 % | 98.9 % | 100.0 % | 0.16 | 4438 | 89.2 % | 97.6 % | 100.0 % |
| view2.png view4.png | 6 | 4479 | 93.5 % | 99.0 % | 100.0 % | 0.17 | 4479 | 87.9 % | 98.0 % | 99.9 % |
| view3.png view4.png | 3 | 1807 | 61.7 % | 67.7 % | 70.5 % | 0.38 | 1807 | 57.5 % | 62.4 % | 63.6 % |
| all pairs |  | 41181 | 92.4 % | 97.5 % | 98.7 % | 0.17 | 41181 | 86.5 % | 96.0 % | 98.3 % |

model: 5/5 images registered, 5944 points
relative rotation error (every pair of images, no alignment): mean 0.007° max 0.010°
after a similarity alignment of the camera centres: centre error mean 0.0011 max 0.0016 (scene units), rotation error mean 0.058° max 0.062°
